"""``python -m labrig.cli``: the ``labrig`` command."""

from labrig.cli import app

app(prog_name="labrig")
