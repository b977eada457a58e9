"""C/C++ controllers (issue 11): ``spinner.h``/``spinner.hpp`` (``include/``), the build
(:mod:`.build`), the child process that runs a program's ``main`` (:mod:`.bridge`, host
``host/spinner_host.c``) and fault symbolisation (:mod:`.symbolize`). docs/c_controllers.md.
"""
from simrunner.run.native.build import (INCLUDE_DIR, NATIVE_SUFFIXES, NativeProgram, build_program,
                                        cflags, is_native)
from simrunner.run.native.bridge import NativeController, load_native

__all__ = ["INCLUDE_DIR", "NATIVE_SUFFIXES", "NativeProgram", "NativeController", "build_program",
           "cflags", "is_native", "load_native"]
