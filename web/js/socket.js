// The session socket's messages: pose frames (drawn, latency measured),
// JSON events (state, constraint sets of collaborators, warnings, errors,
// grabs, peers) and reconnection after the socket drops.

import { ApiError } from './api.js';
import { shouldReconnect } from './dend-client/session.js';
import {
  app, progress, setState, showConstraints, showWarnings, showError, updateStats, uploadPose, refreshCurvature,
  showHeld, clearHeld,
} from './app.js';

const $ = (id) => document.getElementById(id);

/** The stream as the status bar shows it: frames/s over the last second,
 * the settle time (last drag sent → its settled frame), the frame's level. */
const flow = { times: [], lastDragSent: null, settleMs: null, bytes: 0, encodings: {}, levels: [0, 0] };

function showFlow(f, now) {
  flow.times.push(now);
  flow.bytes += f.bytes || 0;
  flow.encodings[f.encoding] = (flow.encodings[f.encoding] || 0) + 1;
  flow.levels[f.level === 1 ? 1 : 0]++;
  while (flow.times.length && flow.times[0] < now - 1000) flow.times.shift();
  if (f.settled && flow.lastDragSent !== null) {
    flow.settleMs = now - flow.lastDragSent;
    flow.lastDragSent = null;
  }
  const fps = $('stFps');
  if (fps) fps.textContent = String(flow.times.length);
  const settle = $('stSettle');
  if (settle) settle.textContent = flow.lastDragSent !== null ? '…' : flow.settleMs === null ? '–' : `${flow.settleMs.toFixed(0)} ms`;
  const level = $('stLevel');
  if (level) level.textContent = f.level === 1 ? 'coarse' : 'full';
  app.flow = { fps: flow.times.length, settleMs: flow.settleMs, level: f.level, bytes: flow.bytes, encoding: f.encoding, encodings: { ...flow.encodings }, levels: [...flow.levels] };
}

function onFrame(f) {
  if (!app.positions || f.positions.length !== app.positions.length) return;
  const now = performance.now();
  for (const [s, t] of app.sent) {
    if (s <= f.ackSeq) {
      app.latencies.push(now - t);
      if (app.latencies.length > 100) app.latencies.shift();
      app.sent.delete(s);
      if (flow.lastDragSent === null || t > flow.lastDragSent) flow.lastDragSent = t;
    }
  }
  showFlow(f, now);
  app.positions = new Float32Array(f.positions);
  app.frames++;
  app.last = f;
  uploadPose();
  updateStats();
  if (f.settled) refreshCurvature();
}

const STAGES = { assembly: 'assembling the system', symbolic: 'symbolic analysis', numeric: 'numeric factorisation' };

/** The factor build's stage (a `build_progress` event, or a state's
 * `build_stage` for a tab that joins mid-build) on the progress line. */
function showStage(stage) {
  progress(stage ? `factor: ${STAGES[stage] || stage}…` : '');
}

function onEvent(e) {
  // the last events, for the browser test's failure messages
  app.eventLog.push(e.type === 'state' ? `state:${e.state}:${e.constraints_revision}` : e.type === 'build_progress' ? `build_progress:${e.stage}` : e.type);
  if (app.eventLog.length > 40) app.eventLog.shift();
  switch (e.type) {
    case 'state':
      if (e.you !== undefined) app.you = e.you;
      setState(e.state);
      $('stPeers').textContent = String(e.peers);
      app.canUndo = !!e.can_undo;
      $('undo').disabled = !e.can_undo && app.settingsUndo.length === 0;
      $('redo').disabled = !e.can_redo;
      // another client's constraint edit (or undo to another set): show it,
      // unless this tab has strokes of its own not applied yet
      if (e.constraints_revision !== undefined && e.constraints_revision !== app.constraintsRevision && !app.dirtyLabels) {
        showConstraints(e);
      }
      showWarnings(e.warnings || []);
      if (e.state === 'building') showStage(e.build_stage);
      else showStage(null);
      break;
    case 'build_progress':
      showStage(e.stage);
      break;
    case 'ready':
      setState('ready');
      showStage(null);
      break;
    case 'error':
      // a refused drag never gets a frame: not a latency sample
      if (e.seq !== undefined && e.seq !== null) app.sent.delete(e.seq);
      // another client holds the handle: a quiet status, not an error
      if (e.code === 'handle_grabbed') {
        showHeld(e.handle);
        break;
      }
      if ((e.code === 'unknown_handle' || e.code === 'not_ready') && (app.dirtyLabels || !app.applied)) {
        showError({ code: e.code, message: `${e.message} — the painted regions are not applied yet: paint a fixed region and press “Apply constraints”` });
      } else {
        showError(e);
      }
      if (app.state === 'building') {
        setState('failed');
        showStage(null);
      }
      break;
    case 'handle_grabbed':
      if (e.client !== app.you) showHeld(e.handle, e.client);
      break;
    case 'handle_released':
      if (e.client !== app.you) clearHeld(e.handle);
      break;
    case 'peer_joined':
    case 'peer_left':
      if (e.client !== app.you) {
        const n = (+$('stPeers').textContent || 1) + (e.type === 'peer_joined' ? 1 : -1);
        $('stPeers').textContent = String(Math.max(1, n));
      }
      break;
    default:
      break;
  }
}

function onClose(code, reason) {
  app.ws = null;
  setState('disconnected');
  if (code === 1000) return;
  // the package's rule (dend-client's shouldReconnect): 4004, the session
  // closed here (deleted, expired, or taken over by another instance);
  // 4012, handed over (at once); 1001/1006/1011/1012, the server went away;
  // 4000, this tab closed it, a delta frame did not decode. Reopen it
  // while the server says it exists.
  if (app.session && shouldReconnect(code)) {
    reconnect(app.session, code === 4012 ? 0 : 250);
    return;
  }
  showError({ code: `closed_${code}`, message: reason || 'the session socket closed' });
}

/** Reopens `session`'s socket after `delay` ms, doubling up to 2 s while
 * the session is not reachable yet (409 `session_owned_elsewhere` while a
 * failover or hand-over is under way, 503 while the store is down, no
 * answer while the load balancer re-routes); a 404 or another error ends
 * it. Stops when another session was opened meanwhile. */
function reconnect(session, delay) {
  setTimeout(async () => {
    if (app.session !== session || app.ws) return;
    const again = () => reconnect(session, Math.min(Math.max(2 * delay, 250), 2000));
    try {
      await app.api.json('GET', `/v1/sessions/${session.id}`, undefined, session.token);
    } catch (e) {
      // a moving session, a store or instance briefly away, no answer
      const transient = !(e instanceof ApiError) || e.transient;
      if (transient) again();
      else showError(e);
      return;
    }
    try {
      app.ws = await app.api.connect(session.id, session.token, socketHandlers);
    } catch (e) {
      again();
    }
  }, delay);
}

/** The callbacks of `Api.connect`. */
export const socketHandlers = { frame: onFrame, event: onEvent, close: onClose };
