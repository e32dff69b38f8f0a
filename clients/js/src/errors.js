// Typed errors: every failure the client reports is a DendError with a
// machine-readable `code` (the server's own code for API and WebSocket
// errors), so callers branch on codes, not on messages.

/** The base of every error this package throws. */
export class DendError extends Error {
  /** @param {string} code @param {string} message */
  constructor(code, message, options) {
    super(message, options);
    this.name = 'DendError';
    this.code = code;
  }
}

/** The server refused an HTTP request: `code` and `message` are its JSON
 * error body's (api/openapi.yaml, `Error`), `status` the HTTP status.
 * Answers without a JSON error body get the code `http_<status>`. */
export class ApiError extends DendError {
  constructor(code, message, status, retryAfter = null) {
    super(code, message);
    this.name = 'ApiError';
    this.status = status;
    /** Seconds from a `Retry-After` header (503 overloaded, draining), else null. */
    this.retryAfter = retryAfter;
  }

  /** Whether retrying the same request later may succeed: the session is
   * moving between instances, the store or the instance is briefly
   * unavailable, or the network failed. */
  get transient() {
    return TRANSIENT_CODES.has(this.code) || this.status === 0 || this.status >= 502;
  }
}

/** Codes after which the same request may succeed a moment later. */
const TRANSIENT_CODES = new Set([
  'session_owned_elsewhere', 'store_unavailable', 'overloaded', 'draining', 'timeout', 'network',
]);

/** The kinds of malformed frame, as `dend_protocol::FrameError`'s variants. */
export const FRAME_ERROR_KINDS = ['length', 'magic', 'version', 'encoding', 'level', 'box', 'delta', 'base'];

/** A binary pose frame that does not decode. `kind` names the check that
 * failed (the Rust decoder's `FrameError` variant, lower case); `code` is
 * `frame_<kind>`. The other fields carry the variant's data: `got` and
 * `expected` (length), `value` (version, encoding, level), `base` and
 * `have` (a delta frame against a frame the decoder does not hold). */
export class FrameError extends DendError {
  constructor(kind, message, details = {}) {
    super(`frame_${kind}`, message);
    this.name = 'FrameError';
    this.kind = kind;
    Object.assign(this, details);
  }
}

/** An `error` event of the session socket (a refused drag carries its `seq`). */
export class SessionError extends DendError {
  constructor(code, message, seq = null) {
    super(code, message);
    this.name = 'SessionError';
    this.seq = seq;
  }
}

/** The session socket could not be opened or closed for good: `closeCode`
 * is the WebSocket close code (4001 missing token, 4003 wrong token, 4004
 * session closed, ...), or null when it never opened. */
export class ConnectionError extends DendError {
  constructor(code, message, closeCode = null, cause = undefined) {
    super(code, message, cause === undefined ? undefined : { cause });
    this.name = 'ConnectionError';
    this.closeCode = closeCode;
  }
}
