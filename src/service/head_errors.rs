//! Problem bodies for the answers hyper writes itself. A request head hyper cannot parse is
//! answered by hyper, before the application sees a request: 400 (malformed request line or
//! header), 414 (request target too long) or 431 (head over hyper's buffer or 100 header
//! fields), each with an empty body, and the connection is closed. hyper has no hook for
//! that answer, so this wrapper of the connection's IO recognises it on its way out and
//! sends an RFC 9457 problem instead.
//!
//! Recognised exactly: a single write that is one whole response head (it ends with the
//! blank line and holds no other) whose status is 400, 414 or 431, with `content-length: 0`
//! and no `content-type`. Every answer of the application carries a body and a content
//! type, and no body this server writes ends with a blank line, so nothing else matches.

use hyper::rt::{Read, ReadBufCursor, Write};
use std::io;
use std::pin::Pin;
use std::task::{ready, Context, Poll};

/// The connection's IO, with hyper's own error answers rewritten.
pub struct ProblemAnswers<T> {
    inner: T,
    /// Base of problem `type` URLs (`--public-url`, or empty: relative).
    base: std::sync::Arc<str>,
    /// A rewritten answer being written, and how much of it is out; the caller's write it
    /// replaces is reported done once all of it is.
    pending: Option<(Vec<u8>, usize)>,
}

impl<T> ProblemAnswers<T> {
    /// Wrap `inner`; problem types are absolute under `base` when it is not empty.
    pub fn new(inner: T, base: std::sync::Arc<str>) -> Self {
        Self {
            inner,
            base,
            pending: None,
        }
    }
}

/// The problem answer that replaces `head`, when `head` is one of hyper's own.
fn replacement(head: &[u8], base: &str) -> Option<Vec<u8>> {
    // Cheap tests first: every write of every response passes here, bodies of many MB too.
    if head.len() > 1024 || !head.starts_with(b"HTTP/1.") || !head.ends_with(b"\r\n\r\n") {
        return None;
    }
    let text = std::str::from_utf8(head).ok()?;
    let end = text.find("\r\n\r\n")?;
    if end + 4 != text.len() {
        return None;
    }
    let mut lines = text[..end].split("\r\n");
    let status_line = lines.next()?;
    let (status, slug, detail) = match status_line {
        "HTTP/1.1 400 Bad Request" | "HTTP/1.0 400 Bad Request" => (
            400,
            "bad-request",
            "the request's head could not be parsed as HTTP/1.1: a malformed request line or \
             header field",
        ),
        "HTTP/1.1 414 URI Too Long" | "HTTP/1.0 414 URI Too Long" => (
            414,
            "uri-too-long",
            "the request target (the URL's path and query) is longer than the server reads",
        ),
        "HTTP/1.1 431 Request Header Fields Too Large"
        | "HTTP/1.0 431 Request Header Fields Too Large" => (
            431,
            "header-fields-too-large",
            "the request's head is larger than the server reads (about 400 KB, at most 100 \
             header fields)",
        ),
        _ => return None,
    };
    let (mut empty, mut typed, mut date) = (false, false, None);
    for line in lines {
        let (name, value) = line.split_once(':')?;
        let value = value.trim();
        match name.trim().to_ascii_lowercase().as_str() {
            "content-length" => empty = value == "0",
            "content-type" => typed = true,
            "date" => date = Some(value),
            _ => {}
        }
    }
    if !empty || typed {
        return None;
    }
    let title = &status_line[13..];
    let body = serde_json::json!({
        "type": format!("{base}/problems/{slug}"),
        "title": title,
        "status": status,
        "detail": detail,
    })
    .to_string();
    let mut out = format!(
        "{status_line}\r\ncontent-type: {}\r\ncontent-length: {}\r\nconnection: close\r\n",
        super::problem::PROBLEM_JSON,
        body.len()
    );
    if let Some(d) = date {
        out += &format!("date: {d}\r\n");
    }
    out += "\r\n";
    out += &body;
    Some(out.into_bytes())
}

impl<T: Write + Unpin> ProblemAnswers<T> {
    /// Write out the pending answer; Ready once all of it is out.
    fn drive(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while let Some((bytes, done)) = &mut self.pending {
            if *done == bytes.len() {
                self.pending = None;
                break;
            }
            let n = ready!(Pin::new(&mut self.inner).poll_write(cx, &bytes[*done..]))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            *done += n;
        }
        Poll::Ready(Ok(()))
    }
}

impl<T: Read + Unpin> Read for ProblemAnswers<T> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: ReadBufCursor<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<T: Write + Unpin> Write for ProblemAnswers<T> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if this.pending.is_none() {
            match replacement(buf, &this.base) {
                Some(answer) => this.pending = Some((answer, 0)),
                None => return Pin::new(&mut this.inner).poll_write(cx, buf),
            }
        }
        // The caller retries the same write until it is reported done.
        ready!(this.drive(cx))?;
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let mut non_empty = bufs.iter().filter(|b| !b.is_empty());
        if let (Some(only), None) = (non_empty.next(), non_empty.next()) {
            if this.pending.is_some() || replacement(only, &this.base).is_some() {
                return Pin::new(this).poll_write(cx, only);
            }
        }
        Pin::new(&mut this.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        ready!(this.drive(cx))?;
        Pin::new(&mut this.inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        ready!(this.drive(cx))?;
        Pin::new(&mut this.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::replacement;

    #[test]
    fn only_hypers_own_empty_answers_are_replaced() {
        let hyper_431 = b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\ndate: Wed, 25 Nov 2026 04:00:00 GMT\r\n\r\n";
        let out = String::from_utf8(replacement(hyper_431, "http://x").unwrap()).unwrap();
        let (head, body) = out.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 431 Request Header Fields Too Large\r\n"));
        assert!(head.contains("content-type: application/problem+json"));
        assert!(head.contains("date: Wed, 25 Nov 2026 04:00:00 GMT"));
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let p: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(p["type"], "http://x/problems/header-fields-too-large");
        assert_eq!(p["status"], 431);
        // Not hyper's: an application answer (typed, with a body), a body chunk that merely
        // starts like a head, another status, a head followed by more.
        for other in [
            &b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/problem+json\r\ncontent-length: 0\r\n\r\n"[..],
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 12\r\n\r\n",
            b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\nmore",
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n",
            b"v 0 0 0\n",
        ] {
            assert_eq!(replacement(other, ""), None, "{}", String::from_utf8_lossy(other));
        }
    }
}
