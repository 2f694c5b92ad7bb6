"""Example scripts: each runs stand-alone (``python -m fixtures_design.examples.<name> [OUT_DIR]``)."""
