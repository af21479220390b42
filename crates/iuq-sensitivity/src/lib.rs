//! iuq-sensitivity
