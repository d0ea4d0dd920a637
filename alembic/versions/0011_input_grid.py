"""descriptors.input_points, input_grid: the organized point cloud a file was

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-27 21:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011"
down_revision: str | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # NULL for a mesh, and for the descriptors made before it was recorded (every cloud
    # enrolled before then was described from its grid as now, but the grid was not kept).
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.add_column(sa.Column("input_points", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("input_grid", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.drop_column("input_grid")
        batch_op.drop_column("input_points")
