//! Workers: claim jobs, run them on blocking threads, heartbeat, report progress.
