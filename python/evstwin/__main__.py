"""``python -m evstwin`` runs the evstwin command."""

from .cli import run

run()
