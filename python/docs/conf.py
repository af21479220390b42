# Sphinx configuration of the Python API reference (built by scripts/docs.sh into
# book/python-api/, beside the book). The docstrings are numpydoc-style; autodoc imports the
# `iuq` package found first on sys.path (scripts/docs.sh puts the source tree's modules there,
# with the installed native extension).
import iuq

project = "iuq"
author = "The iuq maintainers"
copyright = "the iuq maintainers; MIT OR Apache-2.0"
version = release = iuq.__version__

extensions = ["sphinx.ext.autodoc", "numpydoc"]
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_title = f"iuq {release}: the Python API"
html_theme_options = {
    "description": "Inverse uncertainty quantification of expensive simulation models",
    "extra_nav_links": {"The iuq book": "../index.html"},
}
html_static_path = []

autodoc_member_order = "bysource"
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
# Every public function and method documents its parameters, return value and examples.
numpydoc_validation_checks = {"PR01", "PR02", "PR03", "PR10", "RT01", "GL08"}
# Result classes are made by iuq, not by their users, and Study and GaussianProcess by their
# `load`/`fit`: their fields are documented as Attributes, not constructor parameters.
numpydoc_validation_exclude = {
    r"\.__repr__$",
    r"\._repr_html_$",
    r"\.__init__$",
    r"^iuq\.(CalibrationResult|PipelineResult|CampaignStatus|SobolResult|BasisResult|Study|GaussianProcess)$",
}
