"""descriptors.smoothed: whether the surface was smoothed of a scanner's noise

Revision ID: 0013
Revises: 0012
Create Date: 2026-12-03 16:40:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013"
down_revision: str | None = "0012"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # NULL for the descriptors made before it was recorded (their descriptor does not
    # say either).
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.add_column(sa.Column("smoothed", sa.Boolean(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.drop_column("smoothed")
