"""The notebook client's base: paginated listings and ids given as unique prefixes (the 8 characters the CLI
and UI show)."""

from __future__ import annotations

import re
import urllib.parse
from collections.abc import Callable, Iterator
from typing import Any

from app.client.errors import AmbiguousId, api_error
from app.client.transport import ApiClient

HEX_ID = re.compile(r"^[0-9a-f]{32}$")
SHORT_ID_MIN = 4  # shorter prefixes are refused (too many candidates to be useful)


class ClientBase(ApiClient):
    """Listings and short ids, shared by the telemetry and job halves of :class:`app.client.Client`."""

    # -- listings and short ids ---------------------------------------------------------------------
    def pages(self, path: str, **params: Any) -> Iterator[dict[str, Any]]:
        """Every item of a paginated listing (following ``X-Next-Cursor``)."""
        query: dict[str, Any] = {"limit": 500, **params}
        while True:
            _, items, headers = self.request("GET", path, params=query)
            yield from items
            cursor = headers.get("x-next-cursor")
            if not cursor:
                return
            query["cursor"] = cursor

    def _resolve(self, what: str, prefix: str, ids: Callable[[], Iterator[str]]) -> str:
        prefix = prefix.strip().lower()
        if HEX_ID.match(prefix):
            return prefix
        if len(prefix) < SHORT_ID_MIN or not re.fullmatch(r"[0-9a-f]+", prefix):
            raise ValueError(f"{what} id {prefix!r}: expected the full id or at least {SHORT_ID_MIN} of its first "
                             "hexadecimal characters")
        found = sorted({i for i in ids() if i.startswith(prefix)})
        if not found:
            raise api_error(404, {"detail": f"no {what} id starts with {prefix!r}"})
        if len(found) > 1:
            raise AmbiguousId(what, prefix, found)
        return found[0]

    def resolve_job(self, job_id: str) -> str:
        """The full id of a job given by a unique prefix (or its full id)."""
        return self._resolve("job", job_id, lambda: (j["id"] for j in self.pages("/api/v1/jobs")))

    def resolve_ingest(self, spacecraft: str, ingest_id: str) -> str:
        return self._resolve("ingest", ingest_id, lambda: (
            i["ingest_id"] for i in self.pages(f"/api/v1/spacecraft/{_q(spacecraft)}/ingests")))

    def resolve_reference(self, kind: str, dataset_id: str) -> str:
        return self._resolve("reference data set", dataset_id, lambda: (
            d["id"] for d in self.pages("/api/v1/reference", kind=kind)))

    def resolve_schedule(self, name_or_id: str) -> str:
        """A schedule's name or id as the service takes it: a name or full id as given, else a unique id prefix."""
        items = self.list_schedules()
        if any(name_or_id in (s["name"], s["id"]) for s in items):
            return name_or_id
        if not re.fullmatch(r"[0-9a-fA-F]{4,31}", name_or_id):
            return name_or_id  # the service answers 404 (the CLI adds the nearest name)
        return self._resolve("schedule", name_or_id, lambda: (s["id"] for s in items))


def _q(part: str) -> str:
    """A path segment, quoted."""
    return urllib.parse.quote(str(part), safe="")
