"""Plant presets shipped with the package (``paper``, ``paper-continuous``)."""
