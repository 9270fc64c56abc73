"""``python -m heatpf_jax.cli``: the ``heatpf`` command without its console script."""

from heatpf_jax.cli.parser import main

__all__: list[str] = []

raise SystemExit(main())
