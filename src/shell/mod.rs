//! Shell layer.
