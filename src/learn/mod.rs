//! placeholder, filled by the learn work
