# The retrieval service: API (`python -m app`) or a queue worker (`python -m worker`).
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    SHAPES_HOST=0.0.0.0 \
    SHAPES_PORT=8000 \
    SHAPES_DATA_DIR=/data

RUN useradd --create-home --uid 10001 shapes \
    && mkdir -p /data \
    && chown shapes:shapes /data

WORKDIR /srv/modalshape
# Dependencies first (cached while only the code changes).
COPY pyproject.toml README.m[d] ./
COPY worker ./worker
COPY app ./app
COPY alembic ./alembic
COPY alembic.ini ./
# Editable install: the service finds alembic.ini and alembic/ next to app/.
# The postgres and redis extras: the same image serves docker-compose.scale.yml.
RUN pip install -e ".[postgres,redis]" && python -c "import app.main, worker.jobs.queue, psycopg, redis"

USER shapes
VOLUME ["/data"]
EXPOSE 8000

HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen(f\"http://127.0.0.1:{os.environ.get('SHAPES_PORT', '8000')}/health\", timeout=4)"]

# Migrations, the API, SHAPES_WORKERS (default 2) enrollment and SHAPES_QUERY_WORKERS
# (default 2) query consumers.
CMD ["python", "-m", "app"]
