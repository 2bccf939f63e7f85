//! The runtime: which timer drives the tick, actors under virtual time, the stale-stream stop, link supervision and a real PTY.

mod link_supervision;
mod serial_pty;
mod stale_stream;
mod startup;
mod tick_timer;
mod virtual_time;
