# feedsched HTTP service: `docker build -t feedsched . && docker run -p 8000:8000 feedsched`
FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 \
    FEEDSCHED_DATA_DIR=/data HOST=0.0.0.0 PORT=8000
RUN useradd --create-home --uid 10001 app && mkdir -p /data && chown app:app /data
WORKDIR /app
COPY pyproject.toml requirements.lock README.md ./
COPY geometry geometry
COPY solvers solvers
COPY service service
# the versions of the checked-in lock, as `make run` installs them
RUN pip install --no-cache-dir -c requirements.lock '.[dask]'
USER app
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s CMD python -c "import urllib.request,os; urllib.request.urlopen(f'http://127.0.0.1:{os.environ[\"PORT\"]}/healthz', timeout=4)"
# the equivalent of `make run` (HOST/PORT configurable)
CMD ["sh", "-c", "exec python -m uvicorn service.app:app --host \"$HOST\" --port \"$PORT\""]
