# Slim image running the service with uvicorn as a non-root user.
# It listens on 0.0.0.0, so it refuses to start until a key exists: run it with
# -e ATTITUDE_BOOTSTRAP_TOKEN=<secret> (or a catalog that already has keys).
FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY app app
COPY processing processing
COPY storage storage
COPY migrations migrations
RUN pip install --no-cache-dir --prefix=/install ".[postgres]"

FROM python:3.11-slim
RUN useradd --create-home --uid 10001 attitude && mkdir -p /data && chown attitude /data
COPY --from=build /install /usr/local
USER attitude
ENV ATTITUDE_DATA_DIR=/data
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz')"
CMD ["attitude", "serve", "--host", "0.0.0.0", "--port", "8000"]
