"""geocert: certified global optima of multiview-geometry problems, as a service and a library.

Subpackages: ``geocert.solvers`` (pure numerics), ``geocert.workers`` (Celery tasks and the Redis
job store), ``geocert.app`` (the HTTP API and the command line).
"""

__version__ = "0.2.0"
