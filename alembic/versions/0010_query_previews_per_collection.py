"""query_previews: kept per collection, so one collection's never reach another's

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-26 15:00:00

The previews are a cache of recent queries: the table is made again, empty.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _drop() -> None:
    op.drop_index(op.f("ix_query_previews_created_at"), table_name="query_previews")
    op.drop_table("query_previews")


def upgrade() -> None:
    _drop()
    op.create_table(
        "query_previews",
        sa.Column("collection_id", sa.Integer(), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("glb", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["collection_id"],
            ["collections.id"],
            name=op.f("fk_query_previews_collection_id_collections"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("collection_id", "sha256", name=op.f("pk_query_previews")),
    )
    op.create_index(
        op.f("ix_query_previews_created_at"), "query_previews", ["created_at"], unique=False
    )


def downgrade() -> None:
    _drop()
    op.create_table(
        "query_previews",
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("glb", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("sha256", name=op.f("pk_query_previews")),
    )
    op.create_index(
        op.f("ix_query_previews_created_at"), "query_previews", ["created_at"], unique=False
    )
