"""previews: a small GLB and a PNG thumbnail per described mesh

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 14:20:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "previews",
        sa.Column("mesh_id", sa.Integer(), nullable=False),
        sa.Column("glb", sa.LargeBinary(), nullable=False),
        sa.Column("png", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["mesh_id"],
            ["meshes.id"],
            name=op.f("fk_previews_mesh_id_meshes"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("mesh_id", name=op.f("pk_previews")),
    )


def downgrade() -> None:
    op.drop_table("previews")
