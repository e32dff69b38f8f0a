// The session WebSocket (api/ws-protocol.md): flow-controlled frames
// decoded and acknowledged, drags numbered and kept until a frame
// acknowledges them, and reconnection (a hand-over's 4012, a failover, a
// restart) that sends again exactly the drags the server did not apply.

import { FrameDecoder } from './frame.js';
import { ApiError, ConnectionError, FrameError, SessionError } from './errors.js';

/** Close codes after which the socket is reopened: the server went away
 * (1001, 1006, 1011, 1012), the session closed here but may live on
 * another instance (4004: checked over HTTP first), it moved (4012, at
 * once), or this client closed it because a delta frame lost its base
 * (4000: the new connection starts with a key frame). */
export const RECONNECT_CODES = Object.freeze([1001, 1005, 1006, 1011, 1012, 1013, 4000, 4004, 4012]);

/** Error codes of a refused drag that is sent again (with a new seq):
 * the server did not apply it and says a later try may succeed. */
export const RESEND_CODES = Object.freeze(['store_unavailable', 'rate_limited', 'not_ready']);

/** Whether a socket closed with `code` should be reopened. */
export function shouldReconnect(code) {
  return RECONNECT_CODES.includes(code);
}

/** The drag body of a delta `{translate, rotate | quaternion}`. */
export function deltaBody(delta = {}) {
  const out = {};
  if (delta.translate) out.translate = Array.from(delta.translate);
  if (delta.rotate) out.rotate = { axis: Array.from(delta.rotate.axis), degrees: delta.rotate.degrees };
  if (delta.quaternion) out.quaternion = Array.from(delta.quaternion);
  if (out.rotate && out.quaternion) throw new TypeError('a drag rotates by `rotate` or by `quaternion`, not both');
  return out;
}

const now = () => (typeof performance !== 'undefined' ? performance.now() : Date.now());

/** A session's live socket. Made by `Session.connect(options)`; options:
 * - `window` (1), `encoding` (`'delta'`), `maxFps`, `refineFps` (30): the
 *   stream options of api/ws-protocol.md;
 * - `ack`: `'animation'` (after the next animation frame: drawn; the
 *   default in a page), `'frame'` (once the `frame` listeners returned; the
 *   default elsewhere) or `'manual'` ({@link SessionSocket#ack});
 * - `reconnect` (true), `reconnectTimeoutMs` (60000): how long to keep
 *   trying before giving up with a `close` event;
 * - `resyncTimeoutMs` (3000): how long a reopened socket waits for its
 *   first frame before asking the pose's `ack_seq` over HTTP;
 * - `openTimeoutMs` (10000): how long an upgrade (or the session check
 *   before a reconnection) may take before it is tried again;
 * - `WebSocket`: a constructor, where there is no global one. */
export class SessionSocket {
  constructor(session, options = {}) {
    this.session = session;
    this.options = {
      window: 1, encoding: 'delta', maxFps: undefined, refineFps: 30, ack: undefined,
      reconnect: true, reconnectTimeoutMs: 60000, resyncTimeoutMs: 3000, openTimeoutMs: 10000, ...options,
    };
    if (!this.options.ack) this.options.ack = typeof requestAnimationFrame === 'function' ? 'animation' : 'frame';
    this.WebSocket = this.options.WebSocket || (session.client && session.client.WebSocket) || globalThis.WebSocket;
    this.listeners = new Map();
    this.ws = null;
    this.decoder = null;
    this.queue = Promise.resolve();
    this.closed = false;
    /** @type {'connecting'|'open'|'reconnecting'|'closed'} */
    this.status = 'connecting';
    /** The last frame (with positions), or null. */
    this.latest = null;
    /** The last `state` event, or null. */
    this.state = null;
    /** This connection's client id (`you` of the state event). */
    this.clientId = null;
    this.seq = 0;
    /** Drags sent (or waiting to be sent) that no frame acknowledged yet: seq → {msg, sentAt}. */
    this.pending = new Map();
    this.grabbed = new Set();
    // false between a reopened socket and its first frame: drags wait
    this.synced = true;
    this.unacked = 0;
    this.lastAck = -1;
    this.counters = {
      frames: 0, bytes: 0, maxUnacked: 0, reconnects: 0, resent: 0, decodeErrors: 0,
      levels: [0, 0], encodings: { f32: 0, q16: 0, delta: 0 },
    };
    this.frameTimes = [];
    this.latencies = [];
    this.lastDragAt = null;
    this.settleMs = null;
  }

  /** Subscribes to `frame` (a decoded frame), `event` (every JSON
   * message), `state`, `error` (a SessionError or FrameError), `open`,
   * `reconnecting` ({code, reason}), `reconnected`, `close` ({code,
   * reason, error}); returns the function that unsubscribes. */
  on(type, fn) {
    if (!this.listeners.has(type)) this.listeners.set(type, new Set());
    this.listeners.get(type).add(fn);
    return () => this.listeners.get(type).delete(fn);
  }

  emit(type, value) {
    const set = this.listeners.get(type);
    if (!set) return;
    for (const fn of [...set]) {
      try {
        fn(value);
      } catch (e) {
        // a listener's bug must not stop the stream
        setTimeout(() => { throw e; });
      }
    }
  }

  /** The latest positions (x, y, z per vertex), or null before a frame. */
  get positions() { return this.latest ? this.latest.positions : null; }

  /** The latest frame's level: 0 full, 1 coarse preview. */
  get level() { return this.latest ? this.latest.level : 0; }

  /** Whether the latest frame is settled (the server stopped iterating). */
  get settled() { return !!(this.latest && this.latest.settled); }

  /** Whether the latest frame's solve converged. */
  get converged() { return !!(this.latest && this.latest.converged); }

  /** The stream's figures: frames per second over the last second, the
   * drag→frame latencies (last, median, 95th percentile of the last 100
   * drags, ms), the settle time (last drag → its settled frame), bytes
   * and frames received, the most frames ever held unacknowledged, drags
   * not acknowledged yet, reconnections and drags sent again. */
  stats() {
    const t = now();
    while (this.frameTimes.length && this.frameTimes[0] < t - 1000) this.frameTimes.shift();
    const sorted = [...this.latencies].sort((a, b) => a - b);
    const pct = (p) => (sorted.length ? sorted[Math.min(sorted.length - 1, Math.floor(p * sorted.length))] : null);
    return {
      fps: this.frameTimes.length,
      latencyMs: this.latencies.length ? this.latencies[this.latencies.length - 1] : null,
      latencyP50Ms: pct(0.5),
      latencyP95Ms: pct(0.95),
      settleMs: this.settleMs,
      frames: this.counters.frames,
      bytes: this.counters.bytes,
      levels: [...this.counters.levels],
      encodings: { ...this.counters.encodings },
      unacked: this.unacked,
      maxUnacked: this.counters.maxUnacked,
      pendingDrags: this.pending.size,
      reconnects: this.counters.reconnects,
      resentDrags: this.counters.resent,
      decodeErrors: this.counters.decodeErrors,
    };
  }

  /** Opens the socket; resolves with this once open. Rejects with a
   * ConnectionError (or the ApiError that explains it: a wrong token, a
   * session that does not exist). */
  async open() {
    try {
      await this.connectOnce();
    } catch (e) {
      this.status = 'closed';
      this.closed = true;
      // the browser hides the upgrade's HTTP answer: ask for the reason
      try {
        await this.session.info();
      } catch (why) {
        if (why instanceof ApiError) throw why;
      }
      throw e;
    }
    this.status = 'open';
    this.emit('open');
    return this;
  }

  connectOnce() {
    if (typeof this.WebSocket !== 'function') {
      return Promise.reject(new ConnectionError('no_websocket', 'no WebSocket implementation: pass options.WebSocket'));
    }
    const o = this.options;
    const url = this.session.socketUrl({ window: o.window, encoding: o.encoding, maxFps: o.maxFps, refineFps: o.refineFps });
    let ws;
    try {
      ws = new this.WebSocket(url);
    } catch (e) {
      return Promise.reject(new ConnectionError('ws_failed', `could not open the session WebSocket: ${e.message}`, null, e));
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    this.decoder = new FrameDecoder();
    this.unacked = 0;
    this.lastAck = -1;
    return new Promise((resolve, reject) => {
      let opened = false;
      // an upgrade that hangs (an instance frozen or going away) is given up
      const timer = setTimeout(() => {
        reject(new ConnectionError('ws_timeout', `the session WebSocket did not open in ${this.options.openTimeoutMs} ms`));
        ws.onclose = null;
        ws.close();
      }, this.options.openTimeoutMs);
      ws.onopen = () => {
        clearTimeout(timer);
        opened = true;
        resolve();
      };
      ws.onmessage = (m) => {
        if (ws !== this.ws) return;
        this.queue = this.queue.then(() => this.handle(ws, m.data)).catch((e) => this.emit('error', e));
      };
      ws.onclose = (e) => {
        clearTimeout(timer);
        if (!opened) {
          reject(new ConnectionError('ws_failed', `the session WebSocket did not open (close ${e.code})`, e.code));
          return;
        }
        if (ws === this.ws) this.onClose(e.code, e.reason);
      };
      ws.onerror = () => {};
    });
  }

  async handle(ws, data) {
    if (typeof data === 'string') {
      let msg;
      try {
        msg = JSON.parse(data);
      } catch (_) {
        return;
      }
      this.onEvent(msg);
      return;
    }
    let frame;
    try {
      frame = await this.decoder.decode(data);
    } catch (e) {
      if (!(e instanceof FrameError)) throw e;
      this.counters.decodeErrors++;
      this.emit('error', e);
      const b = new Uint8Array(data);
      if (b.length > 41 && b[41] === 2) {
        // a delta stream that lost its base: a new connection starts with a key frame
        ws.close(4000, 'frame_decode');
      } else {
        // a frame that does not parse is taken (with every frame before it)
        this.sendAck(Number.MAX_SAFE_INTEGER);
      }
      return;
    }
    if (ws !== this.ws) return;
    this.onFrame(frame);
  }

  onFrame(frame) {
    const t = now();
    this.counters.frames++;
    this.counters.bytes += frame.bytes;
    this.counters.levels[frame.level === 1 ? 1 : 0]++;
    this.counters.encodings[frame.encoding]++;
    this.unacked++;
    this.counters.maxUnacked = Math.max(this.counters.maxUnacked, this.unacked);
    this.frameTimes.push(t);
    for (const [seq, d] of this.pending) {
      if (seq > frame.ackSeq) continue;
      if (d.sentAt !== null) {
        this.latencies.push(t - d.sentAt);
        if (this.latencies.length > 100) this.latencies.shift();
      }
      this.pending.delete(seq);
    }
    if (frame.settled && this.lastDragAt !== null && this.pending.size === 0) {
      this.settleMs = t - this.lastDragAt;
      this.lastDragAt = null;
    }
    this.seq = Math.max(this.seq, frame.ackSeq);
    this.latest = frame;
    if (!this.synced) this.resync(frame.ackSeq);
    this.emit('frame', frame);
    const mode = this.options.ack;
    if (mode === 'frame') this.ack(frame);
    else if (mode === 'animation') requestAnimationFrame(() => this.ack(frame));
  }

  /** Acknowledges `frame` (and every frame before it): the server sends
   * the next one. Automatic unless the socket was opened with `ack: 'manual'`. */
  ack(frame = this.latest) {
    if (!frame) return;
    this.sendAck(frame.revision);
  }

  sendAck(revision) {
    if (revision <= this.lastAck) return;
    if (this.sendRaw({ type: 'ack', revision })) {
      this.lastAck = revision;
      this.unacked = 0;
    }
  }

  onEvent(msg) {
    if (msg.type === 'state') {
      this.state = msg;
      if (msg.you !== undefined) this.clientId = msg.you;
      this.emit('state', msg);
    } else if (msg.type === 'error') {
      const err = new SessionError(msg.code, msg.message || msg.code, msg.seq ?? null);
      if (err.seq !== null && this.pending.has(err.seq)) {
        const d = this.pending.get(err.seq);
        this.pending.delete(err.seq);
        if (RESEND_CODES.includes(err.code)) {
          // not applied: again later, as a new drag (a later drag's ack
          // would otherwise count it as applied)
          setTimeout(() => this.queueDrag(d.msg), 250);
        }
      }
      this.emit('error', err);
    }
    this.emit('event', msg);
  }

  /** A reopened socket's first frame says which drags the server holds
   * (`ackSeq`): the ones after it were not applied and are sent again, in
   * order; held handles are grabbed again. */
  resync(ackSeq) {
    this.synced = true;
    clearTimeout(this.resyncTimer);
    for (const h of this.grabbed) this.sendRaw({ type: 'grab', handle: h });
    let resent = 0;
    for (const [seq, d] of [...this.pending]) {
      if (seq <= ackSeq) {
        this.pending.delete(seq);
      } else if (this.sendRaw(d.msg)) {
        if (d.sentAt !== null) resent++;
        d.sentAt = now();
      }
    }
    this.counters.resent += resent;
    this.emit('reconnected', { ackSeq, resent, sent: this.pending.size });
  }

  /** Sends a drag of `handle` (index or name) by `delta` (`translate`,
   * and `rotate` `{axis, degrees}` or `quaternion` `[x,y,z,w]`); returns
   * its seq. It is kept until a frame acknowledges it, and sent again on
   * a new connection if the server did not apply it. */
  drag(handle, delta) {
    return this.queueDrag({ type: 'drag', handle, ...deltaBody(delta) });
  }

  queueDrag(msg) {
    if (this.closed) throw new ConnectionError('closed', 'the session socket is closed');
    const seq = ++this.seq;
    const m = { ...msg, seq };
    const d = { msg: m, sentAt: null };
    this.pending.set(seq, d);
    this.lastDragAt = now();
    if (this.synced && this.sendRaw(m)) d.sentAt = this.lastDragAt;
    return seq;
  }

  /** Sends a JSON message now; false when the socket is not open (it is
   * not queued: drags are, through {@link SessionSocket#drag}). */
  send(msg) { return this.sendRaw(msg); }

  sendRaw(msg) {
    const ws = this.ws;
    if (!ws || ws.readyState !== 1) return false;
    ws.send(JSON.stringify(msg));
    return true;
  }

  /** Holds `handle` exclusively (held again after a reconnection). */
  grab(handle) {
    this.grabbed.add(handle);
    return this.sendRaw({ type: 'grab', handle });
  }

  /** Releases a held handle. */
  release(handle) {
    this.grabbed.delete(handle);
    return this.sendRaw({ type: 'release', handle });
  }

  /** Sets constraints over the socket (`ready` follows, or `error`). */
  setConstraints(constraints, ifRevision) {
    const m = { type: 'set_constraints', constraints };
    if (ifRevision !== undefined && ifRevision !== null) m.if_revision = ifRevision;
    return this.sendRaw(m);
  }

  undo() { return this.sendRaw({ type: 'undo' }); }

  redo() { return this.sendRaw({ type: 'redo' }); }

  savePose(name, { replace } = {}) { return this.sendRaw(replace ? { type: 'save_pose', name, replace: true } : { type: 'save_pose', name }); }

  restorePose(name) { return this.sendRaw({ type: 'restore_pose', name }); }

  ping(nonce) { return this.sendRaw({ type: 'ping', nonce }); }

  /** Resolves with the next frame for which `pred(frame)` holds (any frame
   * by default), rejects after `timeoutMs` or when the socket closes. */
  nextFrame(pred = () => true, timeoutMs = 30000) {
    return new Promise((resolve, reject) => {
      const offs = [];
      const done = (f, v) => { offs.forEach((o) => o()); clearTimeout(timer); f(v); };
      const timer = setTimeout(() => done(reject, new ConnectionError('timeout', `no such frame in ${timeoutMs} ms`)), timeoutMs);
      offs.push(this.on('frame', (fr) => { if (pred(fr)) done(resolve, fr); }));
      offs.push(this.on('close', (c) => done(reject, c.error || new ConnectionError('closed', 'the session socket closed', c.code))));
    });
  }

  /** Resolves with the first settled frame that acknowledges every drag
   * made so far: the latest frame if it is one, else the next such frame. */
  settledFrame(timeoutMs = 60000) {
    const want = this.seq;
    const done = (f) => f.settled && f.ackSeq >= want && this.pending.size === 0;
    if (this.latest && done(this.latest)) return Promise.resolve(this.latest);
    return this.nextFrame(done, timeoutMs);
  }

  onClose(code, reason) {
    this.ws = null;
    if (this.closed) {
      this.finish(code, reason, null);
      return;
    }
    if (code === 4001 || code === 4003 || !this.options.reconnect || !shouldReconnect(code)) {
      this.finish(code, reason, new ConnectionError(`closed_${code}`, reason || `the session socket closed (${code})`, code));
      return;
    }
    this.reconnect(code, reason);
  }

  finish(code, reason, error) {
    this.closed = true;
    this.status = 'closed';
    clearTimeout(this.resyncTimer);
    this.emit('close', { code, reason, error });
  }

  async reconnect(code, reason) {
    this.status = 'reconnecting';
    this.synced = false;
    this.emit('reconnecting', { code, reason });
    const end = Date.now() + this.options.reconnectTimeoutMs;
    let delay = code === 4012 ? 0 : 100;
    for (;;) {
      if (delay) await new Promise((r) => setTimeout(r, delay));
      if (this.closed) return;
      delay = Math.min(Math.max(2 * delay, 100), 2000);
      if (Date.now() > end) {
        this.finish(code, reason, new ConnectionError('reconnect_timeout', `could not reconnect in ${this.options.reconnectTimeoutMs} ms`, code));
        return;
      }
      try {
        // revives a stored session after a restart; says whether it exists
        // (an answer that does not come in time is tried again)
        await Promise.race([this.session.info(), new Promise((_, no) => setTimeout(
          () => no(new ApiError('timeout', 'no answer from the server', 0)), this.options.openTimeoutMs))]);
      } catch (e) {
        if (e instanceof ApiError && !e.transient) {
          this.finish(code, reason, e);
          return;
        }
        continue;
      }
      try {
        await this.connectOnce();
      } catch (_) {
        continue;
      }
      if (this.closed) {
        this.ws.close(1000);
        return;
      }
      this.counters.reconnects++;
      this.status = 'open';
      this.emit('open');
      // no frame (a session without a pose yet): the pose's ack_seq
      this.resyncTimer = setTimeout(() => this.resyncOverHttp(), this.options.resyncTimeoutMs);
      return;
    }
  }

  async resyncOverHttp() {
    if (this.synced || this.closed) return;
    try {
      const pose = await this.session.pose();
      if (!this.synced) this.resync(pose.ack_seq);
    } catch (_) {
      this.resyncTimer = setTimeout(() => this.resyncOverHttp(), this.options.resyncTimeoutMs);
    }
  }

  /** Closes the socket for good (code 1000). */
  close() {
    this.closed = true;
    clearTimeout(this.resyncTimer);
    if (this.ws && this.ws.readyState <= 1) this.ws.close(1000);
    else this.finish(1000, '', null);
  }
}
