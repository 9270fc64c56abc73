"""The command line, ``heatpf``: one module per subcommand, the shared option parsing in one place.

:mod:`~heatpf_jax.cli.parser` builds the parser from each subcommand's ``add_parser`` and holds :func:`main`;
:mod:`~heatpf_jax.cli.run`, :mod:`~heatpf_jax.cli.eval`, :mod:`~heatpf_jax.cli.sweep`, :mod:`~heatpf_jax.cli.tune`,
:mod:`~heatpf_jax.cli.demo`, :mod:`~heatpf_jax.cli.params`, :mod:`~heatpf_jax.cli.colour`,
:mod:`~heatpf_jax.cli.import_rosbag` and :mod:`~heatpf_jax.cli.simulate` are the subcommands;
:mod:`~heatpf_jax.cli.options` (options several of them share) and :mod:`~heatpf_jax.cli.settings` (``--set``,
``--grid``, ``--seeds``) are what they have in common.
"""

from heatpf_jax.cli.options import DEFAULT_BURN_IN, error_stats
from heatpf_jax.cli.params import describe_method
from heatpf_jax.cli.parser import main
from heatpf_jax.cli.run import CSV_HEADER, MODES_HEADER, write_estimates_csv, write_modes_csv
from heatpf_jax.cli.settings import grid_config, parse_grid, parse_seeds, parse_settings

__all__ = [
    "CSV_HEADER",
    "DEFAULT_BURN_IN",
    "MODES_HEADER",
    "describe_method",
    "error_stats",
    "grid_config",
    "main",
    "parse_grid",
    "parse_seeds",
    "parse_settings",
    "write_estimates_csv",
    "write_modes_csv",
]
