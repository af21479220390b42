//! iuq-gp
