//! The per-job report: every metric that applies to a generated dance.
