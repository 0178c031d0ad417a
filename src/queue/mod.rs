//! The durable job queue: the job model, the `JobStore` trait and its SQLite store.
