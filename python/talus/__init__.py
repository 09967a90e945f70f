"""talus from Python: M3C2 on numpy arrays, and change events and volumes between surveys.

- ``talus.m3c2(epoch1, epoch2, corepoints, normal_radii=..., cyl_radius=..., max_distance=...)``:
  M3C2 distances at core points, with py4dgeo's argument names, as numpy arrays;
- ``talus.compare(before, after, out=...)`` and ``talus.campaign([...], out=...)``: the commands on
  files, returning a :class:`Result` (``.events`` a DataFrame, ``.summary`` a dict);
- ``talus.open(dir)``: the :class:`Result` of a finished run.

Errors are :class:`TalusError` (:class:`InputError` for bad input or parameters) with talus's
message. Ctrl-C stops a run at its next safe point and raises ``KeyboardInterrupt``; the units
finished are kept, and the same call with ``resume=True`` goes on from them.
"""

from . import _talus
from ._api import M3C2Result, campaign, compare, m3c2
from ._result import Result, open
from ._talus import InputError, TalusError

__version__ = _talus.__version__

__all__ = [
    "m3c2",
    "M3C2Result",
    "compare",
    "campaign",
    "open",
    "Result",
    "TalusError",
    "InputError",
]
