"""hazardhunt: find the human behaviours that make a robot's control stack unsafe.

Importing the package registers the environment ``hazardhunt/AGV-v0`` with Gymnasium::

    import gymnasium
    import hazardhunt

    env = gymnasium.make("hazardhunt/AGV-v0", scenario="crossing", field="1.25m", reward="max")
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import gymnasium

__version__ = "0.2.0.dev0"

ENV_ID = "hazardhunt/AGV-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="hazardhunt.env.agv:AGVEnv")


@functools.cache
def source_digest() -> str:
    """A short hash of the package's code and scenario data.

    Recorded with every run: results of one campaign should come from one version of the
    code, and the version number alone does not change with every edit.
    """
    package = Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted([*package.rglob("*.py"), *package.rglob("*.toml")]):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def blas_kernel() -> str:
    """numpy's BLAS library and the kernel it picked for this CPU (``openblas 0.3.31
    Haswell``), or ``unknown``.

    Recorded with every run: a search whose numbers pass through BLAS (the covariance of the
    quality-diversity emitters) draws other episodes with another kernel, so a run reproduces
    from its seed where the kernel is the same (docs/design.md, "Determinism").
    """
    from threadpoolctl import threadpool_info  # imported only when a run is recorded

    libraries = [info for info in threadpool_info() if info.get("user_api") == "blas"]
    # A wheel's library sits in numpy.libs; scipy's own may be loaded beside it.
    numpys = [info for info in libraries if "numpy" in Path(info["filepath"]).parent.name]
    chosen = numpys or libraries
    if not chosen:
        return "unknown"
    keys = ("internal_api", "version", "architecture")
    return " ".join(str(chosen[0][key]) for key in keys if chosen[0].get(key))


__all__ = ["ENV_ID", "__version__", "blas_kernel", "source_digest"]
