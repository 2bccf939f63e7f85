//! The websocket library's own buffers, sized for what this protocol sends, so that a connection costs
//! a few kilobytes of them rather than the library's default 128 KiB read buffer (written to zero when it
//! is first used, so it is resident) and a write buffer that grows until 128 KiB are pending.
//!
//! - **Read**: a client sends small commands (a few hundred bytes of JSON). The read buffer is what one
//!   `read` fills; a larger message (up to `[dashboard] max_message_bytes`, the limit the handshake sets)
//!   still arrives whole: the library grows the buffer to the frame's length, announced in its header,
//!   and reads it in pieces of this size. A message over the limit is refused as before (close code 1009,
//!   counted as `oversize`).
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
