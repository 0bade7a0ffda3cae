//! envhub
