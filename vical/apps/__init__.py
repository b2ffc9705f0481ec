"""vical.apps"""

import sys as _sys

if _sys.argv[:1] == ["-m"]:  # python -m vical.apps.<command>, while Python finds the module: before its imports
    from vical.apps.entry import start_up_of_module as _start_up_of_module

    _start_up_of_module(_sys.orig_argv)
