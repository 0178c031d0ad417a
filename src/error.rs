//! The crate error, wrapping each module's error.
