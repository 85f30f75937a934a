"""Write ``lsm6dsox_config.json``: the LSM6DSOX configuration sequence for a few settings.

The register writes that start streaming are a contract between the Python register driver
(``drivers/lsm6dsox_direct/registers.py``), the emulated chip and the NUCLEO firmware, whose
host tests read this file. ``tests/test_lsm6dsox_direct.py`` checks that the file equals
:func:`configuration_sequence`; after a deliberate change to the sequence, regenerate it:

    python tests/vectors/make_lsm6dsox_config.py > tests/vectors/lsm6dsox_config.json
"""

from __future__ import annotations

import json
import re
import sys

from drivers.lsm6dsox_direct.registers import configuration_vectors


def render() -> str:
    """The JSON text, with each [register, value] pair on one line."""
    text = json.dumps(configuration_vectors(), indent=2)
    return re.sub(r"\[\s+(\d+),\s+(\d+)\s+\]", r"[\1, \2]", text) + "\n"


if __name__ == "__main__":
    sys.stdout.write(render())
