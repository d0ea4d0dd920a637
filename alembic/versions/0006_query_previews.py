"""query_previews: recent query previews, shared by every API replica

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-26 02:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
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


def downgrade() -> None:
    op.drop_index(op.f("ix_query_previews_created_at"), table_name="query_previews")
    op.drop_table("query_previews")
