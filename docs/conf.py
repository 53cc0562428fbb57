"""Sphinx configuration of the crop_sim_ros manual (Sphinx + MyST-Parser + Furo, as Gymnasium's).

Built offline (no intersphinx, nothing fetched) with warnings as errors:
``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (``./farm docs``; ``test/test_docs.py``).
The reference tables are generated from the code by ``docs/_ext/crop_sim_docs.py``.
"""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path[:0] = [str(DOCS / "_ext"), str(DOCS.parent)]

project = "crop_sim_ros"
author = "crop_sim_ros contributors"
copyright = "the crop_sim_ros contributors"

extensions = ["myst_parser", "sphinxarg.ext", "crop_sim_docs"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "_ext"]
myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3

html_theme = "furo"
html_title = "crop_sim_ros"
html_static_path = []
html_show_sourcelink = False
