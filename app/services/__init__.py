"""The service layer: the operations on the catalog and the stores that the API and the web UI share.

One module per resource (spacecraft, telemetry, jobs, schedules, keys, reference, exports, trends,
coverage). Services take a SQLAlchemy session, the settings or stores, the caller's identity
(:class:`app.services.access.Principal`, for grants) and typed arguments; they return typed values or
raise :mod:`app.services.errors`. They know nothing of HTTP or HTML: app/api maps their errors to
status codes (app/api/errors.py), app/web to its pages (app/web/render.py).
"""
