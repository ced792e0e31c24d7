FROM python:3.11-slim
RUN useradd --create-home app
WORKDIR /app
COPY pyproject.toml README.md ./
COPY geometry geometry
COPY solvers solvers
COPY service service
RUN pip install --no-cache-dir .
USER app
EXPOSE 8000
CMD ["python", "-m", "uvicorn", "service.app:app", "--host", "0.0.0.0", "--port", "8000"]
