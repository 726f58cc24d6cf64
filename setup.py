"""Build occgp's Cython extensions against the system liboctomap.

Every ``ext/_<name>.pyx`` compiles into ``occgp._<name>`` and links the
OctoMap libraries found through ``pkg-config octomap`` (Debian:
``liboctomap-dev``). Set ``OCCGP_CYTHON_DEBUG=1`` to compile with bounds
checking and wrap-around indexing switched back on.
"""

import os
import shlex
import subprocess
from pathlib import Path

import numpy as np
from Cython.Build import cythonize
from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
OPENMP_MODULES = {"_kernel", "_integral", "_octree", "_grid"}


def pkgconfig(package):
    """Return (include_dirs, library_dirs, libraries, extra) for `package`."""
    try:
        cflags = subprocess.run(
            ["pkg-config", "--cflags", package], check=True, capture_output=True, text=True
        ).stdout
        libs = subprocess.run(
            ["pkg-config", "--libs", package], check=True, capture_output=True, text=True
        ).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise SystemExit(
            f"occgp needs {package} found through pkg-config ({exc}). On Debian or "
            "Ubuntu: `sudo apt-get install liboctomap-dev pkg-config`, or run `make test`, "
            "which installs it."
        ) from None
    inc, libdirs, names, extra = [], [], [], []
    for flag in shlex.split(cflags):
        (inc.append(flag[2:]) if flag.startswith("-I") else extra.append(flag))
    for flag in shlex.split(libs):
        if flag.startswith("-L"):
            libdirs.append(flag[2:])
        elif flag.startswith("-l"):
            names.append(flag[2:])
    return inc, libdirs, names, extra


def extensions():
    inc, libdirs, libs, extra = pkgconfig("octomap")
    debug = os.environ.get("OCCGP_CYTHON_DEBUG", "0") not in ("", "0")
    directives = {
        "language_level": 3,
        "boundscheck": debug,
        "wraparound": debug,
        "initializedcheck": debug,
        "cdivision": True,
        "embedsignature": True,
    }
    exts = []
    for pyx in sorted((HERE / "ext").glob("_*.pyx")):
        # the kernel maps run their per-sample loops on OpenMP threads (n_jobs)
        omp = ["-fopenmp"] if pyx.stem in OPENMP_MODULES else []
        exts.append(
            Extension(
                f"occgp.{pyx.stem}",
                [str(pyx.relative_to(HERE))],
                depends=[str(f.relative_to(HERE)) for f in (HERE / "ext").glob("*.[hp]*")
                         if f.suffix in (".h", ".pxd", ".pxi")],
                language="c++",
                include_dirs=[np.get_include(), "ext", *inc],
                library_dirs=libdirs,
                libraries=libs,
                runtime_library_dirs=libdirs,
                extra_compile_args=["-std=c++17", "-O3", "-ffp-contract=off", *omp, *extra],
                extra_link_args=omp,
                define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
            )
        )
    return cythonize(exts, compiler_directives=directives, include_path=["ext"])


setup(ext_modules=extensions())
