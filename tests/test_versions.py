"""The versions a saved result records."""

import platform

import numpy as np
import scipy

import bayespig
from bayespig._versions import RESULT_PACKAGES, format_versions, package_versions, versions_text


def test_the_versions_are_those_of_the_imported_packages():
    versions = package_versions()
    assert tuple(versions) == RESULT_PACKAGES
    assert versions["bayespig"] == bayespig.__version__
    assert (versions["numpy"], versions["scipy"]) == (np.__version__, scipy.__version__)
    assert package_versions(("numpy",), python=True) == {"numpy": np.__version__,
                                                          "python": platform.python_version()}
    assert package_versions(("no-such-package-here",)) == {"no-such-package-here": "unknown"}


def test_the_report_line_names_python_last():
    assert format_versions({"numpy": "2.0", "python": "3.11.7"}) == "numpy 2.0, Python 3.11.7"
    assert versions_text(("bayespig", "numpy")) == (f"bayespig {bayespig.__version__}, numpy {np.__version__}, "
                                                    f"Python {platform.python_version()}")
