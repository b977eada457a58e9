"""The car model: the dartpy multibody (``body``, ``physics``: :class:`CarSim`), the effects
catalogue (``effects``: :class:`EffectSim`, ``make_sim``) that adds what the nominal model
leaves out, and the :class:`CarModel` contract both satisfy (``protocol``).

``CarModel`` is importable without dartpy; ``make_sim`` and the models load it on use.
"""
from simrunner.car.protocol import CarModel

__all__ = ["CarModel", "make_sim"]


def make_sim(car, **carsim_kwargs):
    """:func:`simrunner.car.effects.make_sim` (imports dartpy)."""
    from simrunner.car.effects import make_sim as _make_sim

    return _make_sim(car, **carsim_kwargs)
