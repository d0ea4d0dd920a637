"""descriptors.kept_area_fraction: the described part's share of the file's surface

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-25 17:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # NULL for the descriptors made before it was recorded: not known.
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.add_column(sa.Column("kept_area_fraction", sa.Double(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("descriptors", schema=None) as batch_op:
        batch_op.drop_column("kept_area_fraction")
