//! Recorder placeholder.
