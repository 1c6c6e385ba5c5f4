"""Builds DAQP's vendored C sources into a shared library at install (the project's metadata
is in pyproject.toml). Optional: where no compiler is there, the install goes on and the
first MPC compiles DAQP into the cache (src/equilibrist/native/daqp_library.py)."""

import importlib.util
from pathlib import Path

from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
spec = importlib.util.spec_from_file_location(
    "daqp_library", HERE / "src" / "equilibrist" / "native" / "daqp_library.py")
assert spec is not None and spec.loader is not None
daqp = importlib.util.module_from_spec(spec)
spec.loader.exec_module(daqp)


def rel(path: Path) -> str:
    return path.relative_to(HERE).as_posix()


setup(ext_modules=[Extension(
    daqp.MODULE,
    sources=[rel(p) for p in daqp.c_sources()] + [rel(daqp.DIGEST_SOURCE)],
    include_dirs=[rel(daqp.DAQP_SOURCES / "include")],
    define_macros=[("EQ_DAQP_DIGEST", f'"{daqp.digest()}"')],
    extra_compile_args=list(daqp.INSTALL_FLAGS),
    optional=True,
)])
