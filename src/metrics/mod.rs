//! Dance quality metrics, each with its formula and source.
