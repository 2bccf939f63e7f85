//! The websocket library's own buffers, sized for what this protocol sends: no write buffer (the library's
//! default grows until 128 KiB are pending) and the library's read buffer.
//!
//! - **Read**: the library's default, 128 KiB (written to zero when first used, so it is resident). A
//!   client sends small commands, and 4 KiB would do for them, but a smaller buffer leaves the rest of an
//!   over-size message unread when the connection is refused and closed: the kernel then resets the socket,
//!   and the reset can reach the client before the close frame (1009, counted as `oversize`) that says why.
//!   The abuse test (`tests/e2e/dashboard/abuse.rs`) lost that frame under load with 4 KiB. A lingering
//!   close that reads a refused connection dry would let this shrink; it is not written yet.
//! - **Write**: every message waits in the connection's own bounded queue ([`super::out_queue`]: at most
//!   `[dashboard] client_queue` ticks, one Horde message, the replies), and the connection's writer hands
//!   the socket one message at a time and waits for it to be written. So the library needs to hold no
//!   more than the message being written: with a write buffer of 0 each message goes to the socket at
//!   once, and the library's buffer is never more than one message. It keeps that memory, though, as
//!   large as the largest message the connection was sent, for as long as it is open: so the history a
//!   client gets on connecting goes in messages of at most 8 KiB (`super::history_messages`). A client
//!   that watches the Horde gets messages of up to 32 KiB, and keeps that much.

/// Bytes one read of the socket fills (the library's `read_buffer_size`).
pub(crate) const READ_BUFFER_BYTES: usize = 128 * 1024;

/// Bytes the library gathers before writing to the socket (`write_buffer_size`): none, every message
/// is written as it is sent.
pub(crate) const WRITE_BUFFER_BYTES: usize = 0;
