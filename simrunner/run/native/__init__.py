"""C/C++ controllers (issue 11): ``spinner.h``/``spinner.hpp`` (``include/``), the build
(:mod:`.build`), running a program's ``main`` (:mod:`.controller`) in the simulator's process (:mod:`.inproc`)
or in a child process (:mod:`.bridge`; both hosted by ``host/spinner_host.c``) and fault
symbolisation (:mod:`.symbolize`). docs/c_controllers.md.
"""
from simrunner.run.native.build import (INCLUDE_DIR, NATIVE_SUFFIXES, BuildLimits, BuildWarning,
                                        NativeProgram, build_program, cflags, is_native)
from simrunner.run.native.controller import NativeController, load_native

__all__ = ["INCLUDE_DIR", "NATIVE_SUFFIXES", "BuildLimits", "BuildWarning", "NativeProgram", "NativeController", "build_program",
           "cflags", "is_native", "load_native"]
