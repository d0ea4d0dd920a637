"""Database engine, sessions and the declarative base (schema changes go through Alembic)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from sqlalchemy import MetaData, create_engine, event
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import DisconnectionError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError
from sqlalchemy.orm import DeclarativeBase, Session, sessionmaker

# Stable constraint names, so migrations can refer to them on every backend.
NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


#: What an unreachable, restarting or locked database raises: the request answers 503
#: with ``Retry-After`` (:func:`app.errors.install_error_handlers`), not 500.
DATABASE_ERRORS: tuple[type[Exception], ...] = (OperationalError, InterfaceError, PoolTimeoutError)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)


#: How long a pooled connection's check before use may take: a trivial query that a
#: healthy server answers in a millisecond.
PING_SECONDS = 1.0


def make_engine(url: str, *, timeout_seconds: float | None = None) -> Engine:
    """An engine for ``url``; SQLite gets WAL, foreign keys and a busy timeout.

    With ``timeout_seconds``, a PostgreSQL server that stops answering (frozen, or a
    network gone silent) fails the request within about that long instead of holding it:
    connecting, waiting for a pooled connection and every exchange with the server are
    bounded by it, a pooled connection is checked in ``PING_SECONDS`` before use, and a
    connection that timed out is closed, never reused. The migrations run without one.
    """
    if not url.startswith("sqlite"):
        if timeout_seconds is None:
            return create_engine(url, pool_pre_ping=True)
        return _bounded_postgres_engine(url, timeout_seconds)
    engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30})

    @event.listens_for(engine, "connect")
    def _sqlite_pragmas(dbapi_connection: Any, _record: object) -> None:
        # We emit BEGIN ourselves (below); pysqlite's implicit BEGIN would be DEFERRED.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA busy_timeout=30000")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _sqlite_begin(connection: Connection) -> None:
        # A deferred transaction that reads and then writes fails at once with
        # SQLITE_BUSY when another writer committed in between (WAL snapshot),
        # busy timeout or not. Writers therefore take the write lock up front;
        # read-only units ask for DEFERRED with execution_options(sqlite_begin=...).
        mode = connection.get_execution_options().get("sqlite_begin", "IMMEDIATE")
        connection.exec_driver_sql(f"BEGIN {mode}")

    return engine


def _bounded_postgres_engine(url: str, seconds: float) -> Engine:
    import psycopg  # the postgres extra

    class BoundedConnection(psycopg.Connection[Any]):
        """A psycopg connection whose every exchange with the server (a statement, a
        fetch, a commit) ends within ``deadline`` seconds, or the connection is closed
        and the caller gets an OperationalError (a 503 for a request)."""

        deadline = seconds

        def wait(self, gen: Any, interval: float = 0.1, timeout: float | None = None) -> Any:
            try:
                return super().wait(gen, interval, self.deadline if timeout is None else timeout)
            except psycopg.errors._WaitTimeout:  # psycopg's own: the wait's timeout expired
                self.pgconn.finish()  # mid-exchange: its state is unknown, never reused
                raise psycopg.OperationalError(
                    f"the database did not answer within {self.deadline:g} s"
                ) from None

    engine = create_engine(
        url,
        pool_timeout=seconds,
        # libpq counts whole seconds, at least 2.
        connect_args={"connect_timeout": max(2, round(seconds / 2))},
    )

    @event.listens_for(engine, "do_connect")
    def _connect(_dialect: Any, _record: Any, cargs: Any, cparams: Any) -> Any:
        return BoundedConnection.connect(*cargs, **cparams)

    @event.listens_for(engine, "checkout")
    def _ping(dbapi_connection: Any, _record: Any, _proxy: Any) -> None:
        # SQLAlchemy's pre-ping would wait the whole deadline on a frozen server, then
        # connect again; this one gives up after PING_SECONDS and lets the pool connect.
        dbapi_connection.deadline = PING_SECONDS
        try:
            engine.dialect.do_ping(dbapi_connection)
        except psycopg.Error as exc:
            raise DisconnectionError(str(exc)) from exc
        finally:
            dbapi_connection.deadline = seconds

    return engine


def make_session_factory(engine: Engine, *, read_only: bool = False) -> sessionmaker[Session]:
    """Sessions on ``engine``; ``read_only`` ones do not take SQLite's write lock."""
    if read_only:
        engine = engine.execution_options(sqlite_begin="DEFERRED")
    return sessionmaker(engine, expire_on_commit=False)


@contextmanager
def unit_of_work(factory: Callable[[], Session]) -> Iterator[Session]:
    """A session that commits once at the end, rolls back on error, then runs
    the callbacks registered with :func:`after_commit` (e.g. enqueueing jobs)."""
    session = factory()
    try:
        yield session
        session.commit()
    except BaseException:
        session.rollback()
        raise
    finally:
        callbacks = session.info.pop("after_commit", [])
        session.close()
    for callback in callbacks:
        callback()


def after_commit(session: Session, callback: Callable[[], None]) -> None:
    """Run ``callback`` once the session's transaction has committed."""
    session.info.setdefault("after_commit", []).append(callback)
