"""app.ingest.inflate: every gzip member, any chunking, trailing bytes refused, the limit held."""

from __future__ import annotations

import gzip

import pytest

from app.ingest.inflate import GzipBodyError, GzipInflater, InflatedTooLarge

DATA = [bytes(range(256)) * 40, b"second member\n" * 500, b"third"]
STREAM = b"".join(gzip.compress(d) for d in DATA)


@pytest.mark.parametrize("chunk", [1, 2, 3, 7, 100, 4096, len(STREAM)])
def test_members_across_any_chunk_boundary(chunk):
    inflater = GzipInflater(limit=10**6)
    out = b"".join(inflater.feed(STREAM[i:i + chunk]) for i in range(0, len(STREAM), chunk))
    inflater.close()
    assert out == b"".join(DATA) and inflater.members == 3


@pytest.mark.parametrize(("body", "message"), [
    (STREAM + b"xy", "not gzip data after gzip member 3"),
    (STREAM + b"x", "truncated"),
    (STREAM + b"\x1f", "truncated"),
    (STREAM[:-3], "truncated"),
    (b"", "truncated"),
    (b"plain text", "at the start"),
])
def test_bad_streams(body, message):
    inflater = GzipInflater(limit=10**6)
    with pytest.raises(GzipBodyError, match=message):
        inflater.feed(body)
        inflater.close()


def test_the_inflated_size_is_bounded_while_inflating():
    inflater = GzipInflater(limit=1000)
    with pytest.raises(InflatedTooLarge, match="1000 bytes"):
        inflater.feed(gzip.compress(b"0" * 10**7))
    exact = GzipInflater(limit=len(DATA[0]))
    assert exact.feed(gzip.compress(DATA[0])) == DATA[0]
