"""``python -m labrig``: the command line, as the ``labrig`` script runs it."""

from labrig.cli import app

app(prog_name="labrig")
