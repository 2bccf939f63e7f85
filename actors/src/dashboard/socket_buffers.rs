//! The websocket library's own buffers, sized for what this protocol sends: no write buffer (the library's
//! default grows until 128 KiB are pending) and a read buffer of 4 KiB.
//!
//! - **Read**: 4 KiB, the most one read of the socket takes (the library writes it to zero when first used,
//!   so it is resident; its default is 128 KiB). A client sends small commands: the largest legal one (a
//!   `save_weights` or `start_recording` with a 100-character name, a `set_params`) is a few hundred bytes,
//!   so a burst of them, up to the rate limit's 40, fits one read. A message larger than this buffer, up to
//!   `[dashboard] max_message_bytes`, is still read whole (the library makes room for a frame as its
//!   header announces it). One over the limit is refused by its header with the rest of it unread; the
//!   connection's lingering close (`super::linger`) reads that rest and throws it away, so the close frame
//!   (1009) that says why is not lost to a reset (with a plain close it was, under load: the abuse test
//!   `tests/e2e/dashboard/abuse.rs` caught it with this buffer before the linger was written).
//! - **Write**: every message waits in the connection's own bounded queue ([`super::out_queue`]: at most
//!   `[dashboard] client_queue` ticks, one Horde message, the replies), and the connection's writer hands
//!   the socket one message at a time and waits for it to be written. So the library needs to hold no
//!   more than the message being written: with a write buffer of 0 each message goes to the socket at
//!   once, and the library's buffer is never more than one message. It keeps that memory, though, as
//!   large as the largest message the connection was sent, for as long as it is open: so the history a
//!   client gets on connecting goes in messages of at most 8 KiB (`super::history_messages`). A client
//!   that watches the Horde gets messages of up to 32 KiB, and keeps that much.

/// Bytes one read of the socket fills (the library's `read_buffer_size`).
pub(crate) const READ_BUFFER_BYTES: usize = 4 * 1024;

/// Bytes the library gathers before writing to the socket (`write_buffer_size`): none, every message
/// is written as it is sent.
pub(crate) const WRITE_BUFFER_BYTES: usize = 0;
