"""Gymnasium environment of the simulator: ``import simrunner.gym`` registers ``NXPCup-v0``
(:class:`simrunner.gym.env.NXPCupEnv`; docs/gym.md).

Gymnasium is an optional extra (``pip install 'nxpcup-sim[gym]'``); without it, importing
this package raises an ``ImportError`` whose message is the one line to act on.
"""
from __future__ import annotations

try:
    import gymnasium
except ModuleNotFoundError as exc:  # pragma: no cover - depends on the installation
    if (exc.name or "").partition(".")[0] != "gymnasium":
        raise
    raise ImportError("simrunner.gym needs Gymnasium, which is not installed: "
                      "pip install 'nxpcup-sim[gym]'") from None

ENV_ID = "NXPCup-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="simrunner.gym.env:NXPCupEnv",
                       disable_env_checker=False)


def __getattr__(name: str):
    if name == "NXPCupEnv":  # the class loads dartpy: only on use
        from simrunner.gym.env import NXPCupEnv

        return NXPCupEnv
    raise AttributeError(f"module 'simrunner.gym' has no attribute {name!r}")


__all__ = ["ENV_ID", "NXPCupEnv"]
