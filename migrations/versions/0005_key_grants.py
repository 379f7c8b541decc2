"""Per-spacecraft grants of API keys.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("api_key") as batch:
        batch.add_column(sa.Column("all_spacecraft", sa.Boolean(), nullable=False, server_default=sa.true()))
    op.create_table(
        "api_key_grant",
        sa.Column("key_id", sa.String(32), sa.ForeignKey("api_key.id", ondelete="CASCADE"), primary_key=True),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  primary_key=True),
    )


def downgrade() -> None:
    op.drop_table("api_key_grant")
    with op.batch_alter_table("api_key") as batch:
        batch.drop_column("all_spacecraft")
