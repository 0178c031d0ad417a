//! Layered configuration: `config.toml`, then `CHOREO_*` environment, then CLI flags.
