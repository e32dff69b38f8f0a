//! Upload size limit: refused from `Content-Length` before reading, or
//! while streaming, without the server's memory growing (this test is alone
//! in its process so the RSS check sees only it).

use std::time::Duration;

use dend_server::Config;
use dend_testkit::server::start;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Resident set size of this process in bytes (Linux), if known.
fn rss() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

#[tokio::test]
async fn oversize_upload_is_413_without_buffering() {
    let limit = 1 << 20;
    let (base, _state) = start(Config {
        max_upload_bytes: limit,
        ..Config::default()
    })
    .await;
    let addr = base.trim_start_matches("http://").to_owned();
    let before = rss();

    // 1. A declared 10 GB body: answered from the headers alone.
    let mut sock = tokio::net::TcpStream::connect(&addr)
        .await
        .expect("connect");
    let head = format!(
        "POST /v1/meshes HTTP/1.1\r\nhost: {addr}\r\ncontent-type: application/json\r\ncontent-length: 10000000000\r\n\r\n"
    );
    sock.write_all(head.as_bytes()).await.expect("write");
    let mut buf = vec![0u8; 4096];
    let n = tokio::time::timeout(Duration::from_secs(10), sock.read(&mut buf))
        .await
        .expect("answer before any body byte")
        .expect("read");
    let answer = String::from_utf8_lossy(&buf[..n]);
    assert!(answer.starts_with("HTTP/1.1 413"), "{answer}");
    assert!(answer.contains("payload_too_large"), "{answer}");

    // 2. A chunked body (no Content-Length) over the limit: cut off while streaming.
    static CHUNK: [u8; 64 << 10] = [b' '; 64 << 10];
    let chunks = futures_util::stream::iter(
        (0..1024).map(|_| Ok::<_, std::io::Error>(bytes::Bytes::from_static(&CHUNK))),
    );
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/meshes"))
        .header("content-type", "application/json")
        .body(reqwest::Body::wrap_stream(chunks))
        .send()
        .await;
    if let Ok(r) = r {
        assert_eq!(r.status().as_u16(), 413);
    } // else: the server closed the connection after answering, also a refusal

    if let (Some(b), Some(a)) = (before, rss()) {
        // 64 MiB were offered; buffering them would show
        assert!(
            a < b + (24 << 20),
            "RSS grew by {} bytes",
            a.saturating_sub(b)
        );
    }
}
