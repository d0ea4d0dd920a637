"""collections: many galleries in one service; today's meshes move to "default"

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-26 04:00:00
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    collections = op.create_table(
        "collections",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("units", sa.String(length=16), nullable=False),
        sa.Column("preset", sa.String(length=64), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_collections")),
        sa.UniqueConstraint("name", name=op.f("uq_collections_name")),
        sqlite_autoincrement=True,
    )
    now = datetime.now(UTC).replace(tzinfo=None)
    op.bulk_insert(
        collections,
        [{"id": 1, "name": "default", "units": "any", "preset": None, "created_at": now}],
    )
    if op.get_bind().dialect.name == "postgresql":  # the next id after the explicit 1
        op.execute("SELECT setval('collections_id_seq', 1)")
    # Every mesh so far is the default collection's; so is a row written without a
    # collection (an API process of the previous version, during a rolling upgrade).
    with op.batch_alter_table(
        "meshes", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.add_column(
            sa.Column("collection_id", sa.Integer(), nullable=False, server_default="1")
        )
        batch_op.drop_constraint(batch_op.f("uq_meshes_sha256"), type_="unique")
        batch_op.create_unique_constraint(
            batch_op.f("uq_meshes_collection_id"), ["collection_id", "sha256"]
        )
        batch_op.create_index(batch_op.f("ix_meshes_sha256"), ["sha256"], unique=False)
        batch_op.create_index(batch_op.f("ix_meshes_collection_id"), ["collection_id"])
        batch_op.create_foreign_key(
            batch_op.f("fk_meshes_collection_id_collections"),
            "collections",
            ["collection_id"],
            ["id"],
            ondelete="CASCADE",
        )
    with op.batch_alter_table("gallery_changes", schema=None) as batch_op:
        batch_op.add_column(
            sa.Column("collection_id", sa.Integer(), nullable=False, server_default="1")
        )
        batch_op.create_index(batch_op.f("ix_gallery_changes_collection_id"), ["collection_id"])


def downgrade() -> None:
    """Back to one gallery: only the default collection's meshes can stay."""
    for child in ("descriptors", "jobs", "previews"):  # foreign keys are off while migrating
        op.execute(
            f"DELETE FROM {child} WHERE mesh_id IN (SELECT id FROM meshes WHERE collection_id != 1)"
        )
    op.execute("DELETE FROM meshes WHERE collection_id != 1")
    with op.batch_alter_table("gallery_changes", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_gallery_changes_collection_id"))
        batch_op.drop_column("collection_id")
    with op.batch_alter_table(
        "meshes", schema=None, table_kwargs={"sqlite_autoincrement": True}
    ) as batch_op:
        batch_op.drop_constraint(
            batch_op.f("fk_meshes_collection_id_collections"), type_="foreignkey"
        )
        batch_op.drop_index(batch_op.f("ix_meshes_collection_id"))
        batch_op.drop_index(batch_op.f("ix_meshes_sha256"))
        batch_op.drop_constraint(batch_op.f("uq_meshes_collection_id"), type_="unique")
        batch_op.create_unique_constraint(batch_op.f("uq_meshes_sha256"), ["sha256"])
        batch_op.drop_column("collection_id")
    op.drop_table("collections")
