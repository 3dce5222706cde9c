"""The one build step beyond pure Python: navigation's grid search in C.

`astar.c` is plain C99 without Python headers; `services/navigation/native.py` loads the
shared library with ctypes. The extension is optional: without a C compiler the install
still succeeds and navigation plans with scipy's Dijkstra (slower, same paths).
Everything else about the package is in `pyproject.toml`.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "services.navigation._astar",
            ["services/navigation/astar.c"],
            extra_compile_args=["-O3"],
            libraries=["m"],
            optional=True,
        )
    ]
)
