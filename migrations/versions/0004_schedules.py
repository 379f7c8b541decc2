"""Schedules (cron, UTC) and their runs, one row per (schedule, fire time).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "schedule",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("name", sa.String(100), nullable=False, unique=True),
        sa.Column("cron", sa.String(120), nullable=False),
        sa.Column("job_type", sa.String(64), nullable=False),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("reference", sa.JSON(), nullable=False),
        sa.Column("window", sa.String(32), nullable=False),
        sa.Column("window_s", sa.BigInteger(), nullable=True),
        sa.Column("enabled", sa.Boolean(), nullable=False),
        sa.Column("next_fire_at", TS, nullable=True),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("api_key_id", sa.String(32), nullable=True),
    )
    op.create_index("ix_schedule_due", "schedule", ["enabled", "next_fire_at"])
    op.create_table(
        "schedule_run",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("schedule_id", sa.String(32), sa.ForeignKey("schedule.id", ondelete="CASCADE"), nullable=False),
        sa.Column("fire_at", TS, nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("job_id", sa.String(32), sa.ForeignKey("job.id", ondelete="SET NULL"), nullable=True),
        sa.Column("missed", sa.Integer(), nullable=False),
        sa.Column("message", sa.Text(), nullable=True),
        sa.Column("fired_by", sa.String(100), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.UniqueConstraint("schedule_id", "fire_at", name="uq_schedule_run_tick"),
    )


def downgrade() -> None:
    op.drop_table("schedule_run")
    op.drop_index("ix_schedule_due", table_name="schedule")
    op.drop_table("schedule")
