"""The service layer, free of FastAPI and Celery: the job runner (a job's items solved and its result
document), the job store in Redis, and the webhook destinations' checks."""
