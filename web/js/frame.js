// The binary pose frames of the session socket: the decoders are the
// JavaScript client package's (clients/js/src/frame.js, served at
// /js/dend-client/), so the project has one decoder, checked against the
// Rust encoder's frames by the package's tests.

export { parseFrame, decodeFrame, FrameDecoder } from './dend-client/frame.js';
export { FrameError } from './dend-client/errors.js';
