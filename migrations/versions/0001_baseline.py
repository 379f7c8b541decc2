"""Baseline catalog: spacecraft, configurations, ingests, telemetry files, API keys.

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "spacecraft",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("name", sa.String(64), nullable=False, unique=True),
        sa.Column("created_at", TS, nullable=False),
    )
    op.create_table(
        "spacecraft_config",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("created_by", sa.String(32), nullable=True),
        sa.UniqueConstraint("spacecraft_id", "version"),
    )
    op.create_table(
        "ingest",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("stream", sa.String(32), nullable=False),
        sa.Column("sensor", sa.String(200), nullable=False),
        sa.Column("rows", sa.Integer(), nullable=False),
        sa.Column("inserted", sa.Integer(), nullable=False),
        sa.Column("duplicates", sa.Integer(), nullable=False),
        sa.Column("start_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("end_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("filename", sa.String(255), nullable=True),
        sa.Column("content_type", sa.String(100), nullable=False),
        sa.Column("size_bytes", sa.BigInteger(), nullable=False),
        sa.Column("checksum_sha256", sa.String(64), nullable=False),
        sa.Column("time_scale", sa.String(8), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("api_key_id", sa.String(32), nullable=True),
    )
    op.create_index("ix_ingest_sc_stream", "ingest", ["spacecraft_id", "stream", "created_at"])
    op.create_table(
        "telemetry_file",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("ingest_id", sa.String(32), sa.ForeignKey("ingest.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("stream", sa.String(32), nullable=False),
        sa.Column("day", sa.Date(), nullable=False),
        sa.Column("path", sa.Text(), nullable=False, unique=True),
        sa.Column("rows", sa.Integer(), nullable=False),
        sa.Column("t_min_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("t_max_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("sensors", sa.String(200), nullable=False),
    )
    op.create_index("ix_tfile_window", "telemetry_file",
                    ["spacecraft_id", "stream", "t_min_tai_ns", "t_max_tai_ns"])
    op.create_table(
        "api_key",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("name", sa.String(100), nullable=False),
        sa.Column("secret_sha256", sa.String(64), nullable=False, unique=True),
        sa.Column("role", sa.String(16), nullable=False),
        sa.Column("created_at", TS, nullable=False),
        sa.Column("expires_at", TS, nullable=True),
        sa.Column("revoked_at", TS, nullable=True),
    )


def downgrade() -> None:
    op.drop_table("api_key")
    op.drop_index("ix_tfile_window", table_name="telemetry_file")
    op.drop_table("telemetry_file")
    op.drop_index("ix_ingest_sc_stream", table_name="ingest")
    op.drop_table("ingest")
    op.drop_table("spacecraft_config")
    op.drop_table("spacecraft")
