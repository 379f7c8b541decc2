"""Reference data sets scoped to one spacecraft (NULL: shared, uploaded by an admin).

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-03
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("reference_dataset") as batch:
        batch.add_column(sa.Column("spacecraft_id", sa.Integer(), nullable=True))
        batch.create_foreign_key("fk_reference_spacecraft", "spacecraft", ["spacecraft_id"], ["id"],
                                 ondelete="CASCADE")
    op.create_index("ix_reference_sc_kind", "reference_dataset", ["spacecraft_id", "kind"])


def downgrade() -> None:
    op.drop_index("ix_reference_sc_kind", table_name="reference_dataset")
    with op.batch_alter_table("reference_dataset") as batch:
        batch.drop_constraint("fk_reference_spacecraft", type_="foreignkey")
        batch.drop_column("spacecraft_id")
