"""One run of a scene on a recording: the scene (a TOML file to a typed, SI-unit config), the
stages it needs and their typed results, the block-streamed conditioning and onsets, the files
a run writes and the exit status behind them.

The orchestration layer: may import every package below it (io, signal, onsets, kinematics,
models, compare, report, runtime); only api, campaign, bench and the command line import it.
"""
