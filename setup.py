"""Builds the native part of the `gaia` Python module with the project's CMake for `pip install .`.

The build directory is GAIA_BUILD_DIR, else ./build; an existing configured one is reused (only the module's
target is built), a missing one is configured for the interpreter running pip. pyproject.toml holds the rest.
"""
import glob
import os
import shutil
import subprocess
import sys

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))


class BuildWithCMake(build_py):
    def run(self):
        super().run()
        build = os.path.abspath(os.environ.get("GAIA_BUILD_DIR") or os.path.join(HERE, "build"))
        if not os.path.exists(os.path.join(build, "CMakeCache.txt")):
            generator = ["-G", "Ninja"] if shutil.which("ninja") else []
            subprocess.check_call(["cmake", "-S", HERE, "-B", build, *generator, "-DCMAKE_BUILD_TYPE=Release",
                                   f"-DGAIA_PYTHON={sys.executable}"])
        subprocess.check_call(["cmake", "--build", build, "--target", "gaia_python"])
        native = glob.glob(os.path.join(build, "python", "gaia", "_gaia*.so"))
        if not native:
            sys.exit(f"setup.py: the build in {build} made no gaia/_gaia module (is pybind11-dev installed?)")
        target = os.path.join(self.build_lib, "gaia")
        os.makedirs(target, exist_ok=True)
        shutil.copy2(native[0], target)


class NativeDistribution(Distribution):
    def has_ext_modules(self):  # a wheel for this platform and Python, not a pure one
        return True


setup(cmdclass={"build_py": BuildWithCMake}, distclass=NativeDistribution)
