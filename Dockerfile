# The shield service alone (numpy, numba, FastAPI, uvicorn; no torch, no client), as a sidecar;
# its compiled core is warmed at build into NUMBA_CACHE_DIR, which then belongs to the user the
# service runs as (numba uses only a cache folder it can write, and that user has no home), so a
# container starts in about a second:
#   docker build -t efsm-shield .
#   docker run -p 8000:8000 -v shield-data:/data -e EFSM_TOKEN=change-me efsm-shield
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    EFSM_HOST=0.0.0.0 \
    EFSM_PORT=8000 \
    EFSM_DATA_DIR=/data \
    NUMBA_CACHE_DIR=/srv/numba-cache

WORKDIR /srv
COPY pyproject.toml README.md LICENSE ./
COPY app ./app
RUN pip install --no-cache-dir ".[service]" \
    && python -m app warm \
    && useradd --system --uid 10001 --no-create-home shield \
    && mkdir -p /data && chown shield /data \
    && chown -R shield "$NUMBA_CACHE_DIR"

USER shield
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
    CMD ["python", "-m", "app.healthcheck"]
CMD ["python", "-m", "app", "serve"]
