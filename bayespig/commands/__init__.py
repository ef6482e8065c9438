"""Sub-commands of the ``bayespig`` command, one module each (``add_*_parser`` and ``run_*``)."""
