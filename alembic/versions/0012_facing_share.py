"""descriptors.facing_share: how much of the surface faces one way (one view near 1)

Revision ID: 0012
Revises: 0011
Create Date: 2026-11-28 00:30:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # NULL for the descriptors made before it was recorded: their searches read it from
    # the descriptor, where it is missing too, so they are not called one view.
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.add_column(sa.Column("facing_share", sa.Double(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.drop_column("facing_share")
