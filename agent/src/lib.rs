//! Agent controller (in progress).
