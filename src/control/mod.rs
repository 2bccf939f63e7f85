//! placeholder, filled by the control work
