"""gallery_changes: the log of shapes added to and removed from the gallery

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-22 15:40:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "gallery_changes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("mesh_id", sa.Integer(), nullable=False),
        sa.Column("action", sa.String(length=8), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_gallery_changes")),
        sqlite_autoincrement=True,
    )


def downgrade() -> None:
    op.drop_table("gallery_changes")
