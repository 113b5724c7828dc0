"""The compiled part of `pip install --no-build-isolation .` (pyproject.toml): demtk._core is built
by the project's own CMake build (target demtk_core), not by setuptools.

The CMake build folder: $DEMTK_BUILD_DIR if set (e.g. build, the one scripts/setup.sh made: then
pip reuses it and only copies), else build/pip (configured once, for the interpreter running pip,
without the C++ tests). The extension must match that interpreter's ABI: CMake is given it as
Python_EXECUTABLE when it configures build/pip.
"""
import glob
import os
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build = os.path.abspath(os.environ.get("DEMTK_BUILD_DIR") or os.path.join(ROOT, "build", "pip"))
        if not os.path.exists(os.path.join(build, "CMakeCache.txt")):
            subprocess.check_call(["cmake", "-S", ROOT, "-B", build, "-DCMAKE_BUILD_TYPE=Release",
                                   f"-DPython_EXECUTABLE={sys.executable}", "-DDEM_BUILD_TESTS=OFF"])
        subprocess.check_call(["cmake", "--build", build, "--target", "demtk_core", "-j", str(os.cpu_count() or 1)])
        built = glob.glob(os.path.join(build, "python", "demtk", "_core*.so"))
        if len(built) != 1:
            raise RuntimeError(f"setup.py: expected one demtk/_core*.so under {build}/python, found {built}")
        dest = self.get_ext_fullpath(ext.name)
        os.makedirs(os.path.dirname(dest), exist_ok=True)
        shutil.copyfile(built[0], dest)


setup(ext_modules=[Extension("demtk._core", sources=[])], cmdclass={"build_ext": CMakeBuild},
      options={"build": {"build_base": os.path.join("build", "setuptools")}})
