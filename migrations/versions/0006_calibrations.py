"""Calibration versions (gyro mounting, scale factor, drift) produced by jobs.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "calibration",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("values", sa.JSON(), nullable=False),
        sa.Column("job_id", sa.String(32), sa.ForeignKey("job.id", ondelete="SET NULL"), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.UniqueConstraint("spacecraft_id", "kind", "version"),
    )


def downgrade() -> None:
    op.drop_table("calibration")
