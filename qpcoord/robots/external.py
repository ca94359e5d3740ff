"""Robot descriptions from the ``example-robot-data`` distribution.

Its PyPI wheel ships the URDF files under ``cmeel.prefix/share/example-robot-data/robots``
but no importable module, so the files are found through the distribution's metadata.
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

__all__ = ["example_robot_data_urdf"]

_PREFIX = "cmeel.prefix/share/example-robot-data/robots/"


def example_robot_data_urdf(relative: str) -> Path:
    """Absolute path of ``robots/<relative>`` inside the installed example-robot-data.

    Raises
    ------
    ValueError
        The distribution is not installed (install ``qpcoord[robots]``) or lacks the file.
    """
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ValueError(
            "this robot needs the 'example-robot-data' package: pip install 'qpcoord[robots]'"
        ) from None
    path = Path(dist.locate_file(_PREFIX + relative))
    if not path.is_file():
        raise ValueError(f"example-robot-data {dist.version} has no file {relative!r}")
    return path
