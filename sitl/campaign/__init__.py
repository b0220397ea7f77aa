"""Monte Carlo robustness campaigns (``quadsitl campaign``).

spec (validated TOML) -> sampling (per-run seeds) -> batch (chunks of runs, an Executor: local
processes or Dask) -> engine + kernels (the numba batch engine, bit-for-bit the scalar runner's
equations) -> results (Parquet parts, resumable) -> summary and figures.

The progress bar needs ``quadsitl[campaign]`` (tqdm); ``--scheduler`` needs ``quadsitl[cluster]``.
"""
