// Guidance from the session's state, not from one demo mesh: the canvas
// prompt and the first line of the help box say what this mesh has and
// what to do next:
// - no regions yet: paint a fixed part and a handle;
// - regions but no handle: add one and paint it;
// - painted but not applied (auto-apply off): apply;
// - a handle: drag it (the prompt goes once the user has dragged).
// It follows the shared state's events (app.js), which never import it.

import { app, events } from './app.js';
import { FIXED } from './regions.js';

const $ = (id) => document.getElementById(id);

/** The step this mesh is at: `none` (no session or no labels), `empty`,
 * `fixed-only`, `unapplied` or `handle`. */
export function step() {
  if (!app.labels) return 'none';
  let fixed = false;
  let handle = false;
  for (const l of app.labels) {
    if (l === FIXED) fixed = true;
    else if (l > 0) handle = true;
  }
  if (!fixed && !handle) return 'empty';
  if (!handle) return 'fixed-only';
  const applied = app.applied && app.applied.json && (app.applied.json.handles || []).length > 0;
  return applied && !app.dirtyLabels ? 'handle' : 'unapplied';
}

const PROMPT = {
  empty: 'Paint the part that stays put (Paint: fixed) and a handle to drag (+ handle), with Brush, Box, Lasso or Fill',
  'fixed-only': 'Now add a handle (+ handle) and paint the part you will drag',
  unapplied: 'Press “Apply constraints” (A) to pose with the painted regions',
  handle: 'Drag the blue handle to pose the mesh',
};

const HELP = {
  empty: '<b>Pose it:</b> this mesh has no regions yet. Paint a <span class="red">fixed</span> part (it stays put) and a <span class="blue">handle</span> (“+ handle”) with Brush, Box, Lasso or Fill; then drag the handle.',
  'fixed-only': '<b>Pose it:</b> the <span class="red">red</span> part stays put; add a <span class="blue">handle</span> (“+ handle”) and paint the part to drag.',
  unapplied: '<b>Pose it:</b> press “Apply constraints” (A) to use the painted regions, then drag the <span class="blue">blue</span> handle.',
  handle: '<b>Pose it:</b> drag the <span class="blue">blue</span> handle (it stays where you drop it; the <span class="red">red</span> parts stay put). Arrows move along an axis, rings turn.',
};

function show() {
  const s = step();
  const prompt = $('prompt');
  if (s === 'none') {
    prompt.hidden = true;
    return;
  }
  prompt.textContent = PROMPT[s];
  prompt.hidden = s === 'handle' && app.dragged;
  prompt.dataset.step = s;
  $('helpPose').innerHTML = HELP[s];
}

/** Follows the state from now on. */
export function attachGuide() {
  for (const type of ['labels', 'session', 'drag']) events.addEventListener(type, show);
  show();
}
