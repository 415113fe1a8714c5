"""The synthetic rig as a generator of recordings for the processing package.

:data:`GENERATOR` is a :class:`meshphase.io.sources.RecordingGenerator` over the registered
scenarios (:mod:`meshphase.synthetic.scenarios`) and :func:`meshphase.synthetic.generate_blocks`.
The package finds it through the entry point ``synthetic`` of the group
``meshphase.sources`` (pyproject.toml), so a scene naming ``synthetic = "SCENARIO"`` runs
without the package importing this one.
"""

from __future__ import annotations

from meshphase.synthetic.config import SynthConfig
from meshphase.synthetic.generate import SyntheticStream, generate_blocks
from meshphase.synthetic.scenarios import get_scenario, list_scenarios

__all__ = ["SyntheticGenerator", "GENERATOR"]


class SyntheticGenerator:
    """The registered synthetic scenarios, generated block by block."""

    def scenarios(self) -> list[str]:
        """Names of the registered scenarios, sorted."""
        return list_scenarios()

    def scenario(self, name: str) -> SynthConfig:
        """Configuration of scenario ``name`` (ValueError listing the known names)."""
        return get_scenario(name)

    def stream(self, scenario_or_config, *, duration: float | None = None,
               seed: int = 0) -> SyntheticStream:
        """The recording of a scenario name or :class:`SynthConfig`, as a deterministic
        stream of blocks (:func:`meshphase.synthetic.generate_blocks`).

        Parameters
        ----------
        scenario_or_config : str or SynthConfig
        duration : float, optional
            Length [s]; default the configuration's.
        seed : int
            Seed of the random draws.
        """
        return generate_blocks(scenario_or_config, duration=duration, seed=seed)


#: The generator the entry point names.
GENERATOR = SyntheticGenerator()
