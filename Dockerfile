FROM python:3.11-slim
WORKDIR /srv/geocert
COPY pyproject.toml README.md ./
COPY geocert ./geocert
RUN pip install --no-cache-dir . && useradd --create-home geocert
USER geocert
EXPOSE 8000
CMD ["geocert", "serve", "--host", "0.0.0.0", "--port", "8000", "--workers", "0"]
