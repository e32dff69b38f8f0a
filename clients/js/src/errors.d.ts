/** The base of every error this package throws. */
export class DendError extends Error {
  constructor(code: string, message: string, options?: { cause?: unknown });
  /** A machine-readable code (the server's own for API and socket errors). */
  code: string;
}

/** The server refused an HTTP request (or could not be reached: `network`, status 0). */
export class ApiError extends DendError {
  constructor(code: string, message: string, status?: number, retryAfter?: number | null);
  /** HTTP status (0 when no answer came). */
  status: number;
  /** Seconds from a `Retry-After` header, or null. */
  retryAfter: number | null;
  /** Whether the same request may succeed a moment later. */
  readonly transient: boolean;
}

/** The check a malformed frame failed (`dend_protocol::FrameError`'s variants). */
export type FrameErrorKind = 'length' | 'magic' | 'version' | 'encoding' | 'level' | 'box' | 'delta' | 'base';

export const FRAME_ERROR_KINDS: readonly FrameErrorKind[];

/** A binary pose frame that does not decode. */
export class FrameError extends DendError {
  constructor(kind: FrameErrorKind, message: string, details?: Partial<Pick<FrameError, 'got' | 'expected' | 'value' | 'base' | 'have'>>);
  kind: FrameErrorKind;
  /** `length`: bytes received. */
  got?: number;
  /** `length`: bytes the header announces. */
  expected?: number;
  /** `version`, `encoding`, `level`: the value read. */
  value?: number;
  /** `base`: the revision the delta frame applies to. */
  base?: number;
  /** `base`: the revision the decoder holds, or null. */
  have?: number | null;
}

/** An `error` event of the session socket. */
export class SessionError extends DendError {
  constructor(code: string, message: string, seq?: number | null);
  /** The seq of the refused drag, or null. */
  seq: number | null;
}

/** The session socket could not be opened, or closed for good. */
export class ConnectionError extends DendError {
  constructor(code: string, message: string, closeCode?: number | null, cause?: unknown);
  /** The WebSocket close code, or null when it never opened. */
  closeCode: number | null;
}
