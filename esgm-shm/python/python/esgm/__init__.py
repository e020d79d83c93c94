"""esgm for Python: time-stamped entity structures and their trajectories (DyKnow's
ESGM), on the embedded runtime (`esgm.InProcess()`) or across the processes of a
system (`esgm.connect(domain)`), with images as numpy arrays over esgm's own memory.

The operations live in the extension module `esgm._esgm` and are re-exported here;
`esgm.worker` serves a unit or sensor written in Python as a supervised worker."""

from ._esgm import *  # noqa: F401,F403  (the extension's public names)
