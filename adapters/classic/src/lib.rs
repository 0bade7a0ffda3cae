//! Classic control (placeholder until the envs land).
