"""Retractions of ingests (who, when, why) and the jobs that had used the retracted samples.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-04
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "ingest_retraction",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("spacecraft_id", sa.Integer(), sa.ForeignKey("spacecraft.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("ingest_id", sa.String(32), nullable=False),  # the ingest row itself is deleted
        sa.Column("stream", sa.String(32), nullable=False),
        sa.Column("sensor", sa.String(200), nullable=False),
        sa.Column("rows", sa.Integer(), nullable=False),
        sa.Column("inserted", sa.Integer(), nullable=False),
        sa.Column("start_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("end_tai_ns", sa.BigInteger(), nullable=False),
        sa.Column("filename", sa.String(255), nullable=True),
        sa.Column("checksum_sha256", sa.String(64), nullable=False),
        sa.Column("uploaded_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("files_removed", sa.Integer(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("retracted_by", sa.String(32), nullable=True),
        sa.Column("retracted_by_name", sa.String(100), nullable=True),
        sa.Column("retracted_at", sa.DateTime(timezone=True), nullable=False),
    )
    op.create_index("ix_retraction_sc", "ingest_retraction", ["spacecraft_id", "retracted_at"])
    op.create_table(
        "job_retraction",
        sa.Column("job_id", sa.String(32), sa.ForeignKey("job.id", ondelete="CASCADE"), primary_key=True),
        sa.Column("retraction_id", sa.String(32), sa.ForeignKey("ingest_retraction.id", ondelete="CASCADE"),
                  primary_key=True),
    )


def downgrade() -> None:
    op.drop_table("job_retraction")
    op.drop_index("ix_retraction_sc", table_name="ingest_retraction")
    op.drop_table("ingest_retraction")
