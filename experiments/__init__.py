"""The example protocols and rig files, shipped with labrig as package data
(``labrig.experiments``): ``labrig run paper`` runs ``paper.yaml`` from any folder
(:mod:`labrig.runner.examples`). Nothing to import here."""
