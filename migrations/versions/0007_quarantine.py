"""Quarantine of damaged telemetry files: the reason and when it was found.

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-02
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("telemetry_file") as batch:
        batch.add_column(sa.Column("quarantined", sa.Text(), nullable=True))
        batch.add_column(sa.Column("quarantined_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("telemetry_file") as batch:
        batch.drop_column("quarantined_at")
        batch.drop_column("quarantined")
