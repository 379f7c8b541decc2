"""The web UI (server-rendered pages under /ui): see app/web/routes.py and app/web/job_pages.py."""

from __future__ import annotations

from fastapi import APIRouter

from app.web import job_pages, manage, routes, viewer

router = APIRouter()
router.include_router(routes.root_router)
router.include_router(job_pages.router)
router.include_router(manage.router)
router.include_router(viewer.data_router)
router.include_router(viewer.router)
router.include_router(routes.router)
