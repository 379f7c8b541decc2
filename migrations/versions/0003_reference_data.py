"""Reference data sets (EOP, GNSS navigation, reference orbits) and the ones a job used.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "reference_dataset",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("kind", sa.String(64), nullable=False),
        sa.Column("name", sa.String(255), nullable=False),
        sa.Column("filename", sa.String(255), nullable=True),
        sa.Column("size_bytes", sa.BigInteger(), nullable=False),
        sa.Column("checksum_sha256", sa.String(64), nullable=False),
        sa.Column("raw_path", sa.Text(), nullable=False),
        sa.Column("parsed_path", sa.Text(), nullable=False),
        sa.Column("rows", sa.Integer(), nullable=False),
        sa.Column("start_tai_ns", sa.BigInteger(), nullable=True),
        sa.Column("end_tai_ns", sa.BigInteger(), nullable=True),
        sa.Column("details", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("api_key_id", sa.String(32), nullable=True),
    )
    op.create_index("ix_reference_kind", "reference_dataset", ["kind", "created_at"])
    with op.batch_alter_table("job") as batch:
        batch.add_column(sa.Column("reference", sa.JSON(), nullable=False, server_default="{}"))


def downgrade() -> None:
    with op.batch_alter_table("job") as batch:
        batch.drop_column("reference")
    op.drop_index("ix_reference_kind", table_name="reference_dataset")
    op.drop_table("reference_dataset")
