//! iuq-doe
