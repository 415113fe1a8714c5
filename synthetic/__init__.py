"""Synthetic rig recordings generated from the models, with their ground truth.

- :mod:`.kinematics`  speed profile (ramp, ripple in Hz, ripple locked to a shaft angle),
                      the speed clock tau(t), exact engagement times
- :mod:`.gauges`      tooth-root strain pulse shape (a function of the gauged gear's angle),
                      face-width load weighting, rendering
- :mod:`.artefacts`   noise (white, 1/f), drift, hum, ADC, clipping, gaps, gain errors
- :mod:`.config`      the typed scenario description (:class:`SynthConfig`)
- :mod:`.scenarios`   the registry of named scenarios (:data:`SCENARIOS`)
- :mod:`.generate`    :func:`generate` (whole) and :func:`generate_blocks` (streamed)
- :mod:`.truth`       :class:`GroundTruth` and its JSON sidecar
- :mod:`.source`      :data:`GENERATOR`, the generator the processing package finds through
                      the ``meshphase.sources`` entry point
- :mod:`.tdms_export` NI TDMS writer for synthetic recordings
- :mod:`.cli`         :func:`cli_synth` behind ``meshphase synth``
"""

from meshphase.synthetic.config import Artefacts, EncoderConfig, GaugeConfig, LoadModulation, SynthConfig, TachoConfig, TiltSource
from meshphase.synthetic.generate import SyntheticStream, generate, generate_blocks
from meshphase.synthetic.kinematics import ShaftRipple, SpeedClock, SpeedProfile
from meshphase.synthetic.scenarios import SCENARIOS, Scenario, describe_scenarios, get_scenario, list_scenarios
from meshphase.synthetic.truth import GroundTruth, truth_path_for
from meshphase.synthetic.cli import cli_synth

__all__ = ["generate", "generate_blocks", "SyntheticStream", "SynthConfig", "GaugeConfig",
           "TachoConfig", "EncoderConfig", "TiltSource", "Artefacts", "LoadModulation", "SpeedProfile", "ShaftRipple", "SpeedClock",
           "SCENARIOS", "Scenario",
           "get_scenario", "list_scenarios", "describe_scenarios", "GroundTruth",
           "truth_path_for", "cli_synth"]
