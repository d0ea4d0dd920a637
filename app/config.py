"""The service's settings: one object, read once from ``SHAPES_*`` environment variables."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator, model_validator

from worker.engine.formats import DEFAULT_MAX_FACES
from worker.engine.presets import DEFAULT_PRESET, get_preset
from worker.jobs.settings import QueueSettings

#: The shortest admin key accepted (the keys the service makes are 32 random bytes).
MIN_API_KEY_LENGTH = 16


class Settings(QueueSettings):
    """Everything configurable about the service.

    Inherits the queue's settings (``data_dir``, ``redis_url``, ``queue_name``,
    ``heartbeat_seconds``) so the API and the workers agree on the queue.
    """

    # Storage (database_url is the queue settings': workers may need it too)
    uploads: Literal["directory", "database"] = Field(
        default="directory",
        description="where uploaded files are kept: <data_dir>/uploads, which every worker "
        "must reach (the embedded default), or the database, so that workers on other hosts "
        "need only the database and Redis URLs",
    )

    # Serving (python -m app)
    host: str = "127.0.0.1"
    port: int = 8000
    workers: int = Field(
        default=2, ge=0, description="enrollment consumer processes started by serve"
    )
    query_workers: int = Field(
        default=2, ge=0, description="query consumer processes started by serve"
    )

    # Access
    api_key: SecretStr | None = Field(
        default=None,
        description="the admin key: when set, every request for a collection's resources "
        "needs a key in the X-API-Key header (this one, or one it made with POST /keys); "
        "unset, the service is open, and serves on a loopback address only",
    )
    open_access: bool = Field(
        default=False,
        description="serve without a key on a non-loopback address (e.g. 0.0.0.0 inside a "
        "container whose port is published on the host's loopback only)",
    )
    cors_origins: list[str] = Field(
        default=[],
        description='browser origins allowed to call the API, e.g. ["https://app.example"]; '
        "none by default (JSON list in SHAPES_CORS_ORIGINS)",
    )

    # The method
    preset: str = Field(
        default=DEFAULT_PRESET, description="preset enrolled meshes are described with"
    )

    # Limits
    max_upload_bytes: int = Field(default=64 * 1024 * 1024, ge=1)
    max_faces: int = Field(default=DEFAULT_MAX_FACES, ge=1)
    max_field_bytes: int = Field(default=64 * 1024, ge=1)
    max_k: int = Field(default=100, ge=1)
    max_page_size: int = Field(default=200, ge=1)

    # Database
    database_timeout_seconds: float = Field(
        default=3.0,
        gt=0,
        description="PostgreSQL: a request whose database does not answer within this "
        "long (connecting, a statement, a commit) answers 503 with Retry-After instead of "
        "waiting (the migrations at start are not bounded)",
    )

    # Jobs
    query_timeout_seconds: float = Field(default=120.0, gt=0)
    query_cache_size: int = Field(
        default=1024, ge=0, description="descriptors of recent query uploads kept in memory"
    )
    verify_cache_size: int = Field(
        default=256,
        ge=0,
        description="enrolled shapes' surfaces as a single view's verification fits on them "
        "(0.5-1 MB each), kept in memory",
    )
    verify_threads: int = Field(
        default=2,
        ge=1,
        description="threads a single view's rigid verification runs on in the API process",
    )
    query_previews_kept: int = Field(
        default=256,
        ge=1,
        description="previews of recent query uploads kept in the database (~70 kB each), "
        "where every replica serves them",
    )
    collector_interval_seconds: float = Field(default=0.5, gt=0)
    stalled_after_seconds: float = Field(
        default=10.0,
        gt=0,
        description="a running job whose heartbeat is older is re-enqueued (workers beat "
        "every heartbeat_seconds, from a thread beside the describing process)",
    )
    sweep_interval_seconds: float = Field(
        default=10.0,
        gt=0,
        description="how often the collector enqueues the jobs the queue does not hold "
        "(accepted while it was down)",
    )
    max_requeues: int = Field(default=2, ge=0)

    # Fusion weights (GET /calibration shows them)
    fusion: Literal["learned", "preset"] = Field(
        default="learned",
        description="learned: the gallery learns its fusion weights from its labelled "
        "shapes by cross-validation and adopts them when they beat the preset's; preset: "
        "always the preset's",
    )
    fusion_weights: dict[str, float] | None = Field(
        default=None,
        description='weights pinned by the operator, e.g. {"gdm": 0, "ddt": 0.5, '
        '"spectrum": 1} (JSON); nothing is learned then',
    )
    fusion_max_shapes: int = Field(
        default=300, ge=9, description="labelled shapes learned on (a stratified sample above)"
    )

    # Calibration (GET /calibration, POST /verify, match confidences)
    calibration_refit_seconds: float = Field(
        default=10.0, ge=0, description="a stale calibration is refitted at most this often"
    )
    calibration_max_pairs: int = Field(
        default=200_000, ge=20, description="labelled pairs scored per fit (a sample above)"
    )

    # Index
    index_refit_fraction: float = Field(
        default=0.05, gt=0, description="refit sigma and projections after this fraction changed"
    )
    index_save_interval_seconds: float = Field(default=30.0, gt=0)
    index_dir: Path | None = Field(
        default=None,
        description="where this API process saves its index; default <data_dir>/index "
        "(API replicas sharing a data directory each need their own)",
    )

    @field_validator("api_key")
    @classmethod
    def _a_key_worth_the_name(cls, key: SecretStr | None) -> SecretStr | None:
        if key is not None and len(key.get_secret_value()) < MIN_API_KEY_LENGTH:
            raise ValueError(
                f"SHAPES_API_KEY must be at least {MIN_API_KEY_LENGTH} characters (a key "
                "anyone can guess protects nothing; e.g. `openssl rand -hex 16`); unset it "
                "to serve openly on this machine"
            )
        return key

    @model_validator(mode="after")
    def _weights_of_the_preset(self) -> Settings:
        if self.fusion_weights is not None:
            fused = set(get_preset(self.preset).fused_modalities)
            if set(self.fusion_weights) != fused:
                raise ValueError(
                    f"SHAPES_FUSION_WEIGHTS must weigh exactly {sorted(fused)} (the preset's "
                    f"modalities), not {sorted(self.fusion_weights)}"
                )
            if any(not w >= 0 for w in self.fusion_weights.values()):
                raise ValueError("SHAPES_FUSION_WEIGHTS must be numbers >= 0")
        return self

    @property
    def sqlalchemy_url(self) -> str:
        return self.database_url or f"sqlite:///{(self.data_dir / 'shapes.sqlite3').resolve()}"

    @property
    def uploads_dir(self) -> Path:
        return self.data_dir / "uploads"

    @property
    def tmp_dir(self) -> Path:
        return self.data_dir / "tmp"

    @property
    def index_directory(self) -> Path:
        return self.index_dir or self.data_dir / "index"

    @property
    def preset_index_directory(self) -> Path:
        """Where the index of the preset's current version is saved."""
        preset = get_preset(self.preset)
        return self.index_directory / f"{preset.name}-v{preset.version}"


#: Addresses only this machine reaches.
LOOPBACK = frozenset({"127.0.0.1", "::1", "localhost"})


def access_notice(settings: Settings) -> str:
    """The sentence the service says at start about who may use it.

    Raises
    ------
    ValueError
        No key, bound to an address other machines reach, and not ``SHAPES_OPEN_ACCESS``:
        the service would be open to anyone on the network, who could delete everything.
    """
    where = f"http://{settings.host}:{settings.port}"
    if settings.api_key is not None:
        return f"API keys required at {where} (SHAPES_API_KEY is the admin key)"
    if settings.host in LOOPBACK:
        return f"no API key (SHAPES_API_KEY): open to everyone on this machine at {where}"
    if settings.open_access:
        return f"no API key, open to everyone who reaches {where} (SHAPES_OPEN_ACCESS)"
    raise ValueError(
        f"refusing to serve on {settings.host} without an API key: anyone on the network "
        "could enroll and delete. Set SHAPES_API_KEY (the admin key), serve on 127.0.0.1, "
        "or set SHAPES_OPEN_ACCESS=true if only trusted clients reach this address."
    )


@lru_cache
def get_settings() -> Settings:
    return Settings()
