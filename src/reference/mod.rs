//! reference (in progress).
