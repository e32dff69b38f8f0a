// The Material section's settings: the server's presets, a stiffness on
// the preset's bending weight, and the paper's parameters (the Advanced
// fold), as session parameters and as snapshots an undo step restores.

import { app } from './app.js';

const $ = (id) => document.getElementById(id);

/** The preset chosen in the menu ({name, label, description, params}), or
 * null when the server lists none. */
export function currentPreset() {
  const list = app.presets ? app.presets.presets : [];
  return list.find((p) => p.name === $('preset').value) || null;
}

/** The stiffness slider's factor on the preset's bending weight β
 * (`bending` in the session parameters): 2^slider, 0.25× to 4×. */
export function stiffnessFactor() {
  return 2 ** Number($('stiffness').value);
}

/** The Advanced fold's fields as session parameters. */
export function advancedParams() {
  const e = $('energy').value;
  const energy = e === 'combined' ? { combined: { ks: +$('ks').value, kb: +$('kb').value } } : e;
  const mode = $('mode').value;
  // the default (elastic) formulation has total curvature or thin plate as
  // its bending energy and no paper mode: the other choices are the
  // paper's eq. (24) least squares
  const elastic = (e === 'total' || e === 'thin-plate') && mode !== 'paper';
  return {
    energy,
    lambda1: $('hard').checked ? 0 : +$('lambda1').value,
    lambda2: +$('lambda2').value,
    detail: $('detail').value,
    mode,
    formulation: elastic ? 'elastic' : 'least_squares',
  };
}

/** Fills the Advanced fold from a preset's parameters (what the server
 * sends; fields it does not name keep their value). */
export function showAdvanced(p) {
  if (!p) return;
  if (typeof p.energy === 'string') $('energy').value = p.energy;
  else if (p.energy && p.energy.combined) {
    $('energy').value = 'combined';
    $('ks').value = p.energy.combined.ks;
    $('kb').value = p.energy.combined.kb;
  }
  $('combinedRow').hidden = $('energy').value !== 'combined';
  if (typeof p.lambda1 === 'number') {
    $('hard').checked = p.lambda1 === 0;
    $('lambda1').disabled = p.lambda1 === 0;
    if (p.lambda1 > 0) $('lambda1').value = p.lambda1;
  }
  if (typeof p.lambda2 === 'number') $('lambda2').value = p.lambda2;
  if (typeof p.detail === 'string') $('detail').value = p.detail;
  if (typeof p.mode === 'string') $('mode').value = p.mode;
}

/** The session parameters of the panel: the preset by name, the fields of
 * the Advanced fold that differ from the preset's (explicit fields
 * override a preset), and the stiffness as the preset's `bending` scaled. */
export function params() {
  const preset = currentPreset();
  const adv = advancedParams();
  if (!preset) return adv;
  const out = { preset: preset.name };
  const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);
  for (const [k, v] of Object.entries(adv)) if (!same(v, preset.params[k])) out[k] = v;
  const f = stiffnessFactor();
  if (f !== 1 && typeof preset.params.bending === 'number') out.bending = preset.params.bending * f;
  return out;
}

/** The panel's settings, to restore them on undo. */
export function settingsSnapshot() {
  const ids = ['preset', 'stiffness', 'energy', 'ks', 'kb', 'lambda1', 'lambda2', 'detail', 'mode'];
  return { values: Object.fromEntries(ids.map((id) => [id, $(id).value])), hard: $('hard').checked };
}

export function restoreSettings(s) {
  for (const [id, v] of Object.entries(s.values)) $(id).value = v;
  $('hard').checked = s.hard;
  $('lambda1').disabled = s.hard;
  $('combinedRow').hidden = $('energy').value !== 'combined';
  showStiffness();
  showPresetInfo();
}

export function showStiffness() {
  const f = stiffnessFactor();
  $('stiffnessOut').textContent = `${f < 1 ? f.toFixed(2) : f.toFixed(f % 1 ? 2 : 0)}×`;
}

export function showPresetInfo() {
  const p = currentPreset();
  $('presetInfo').textContent = p ? p.description || '' : 'the server lists no presets: its defaults';
  // one line in the panel; the whole description as its tooltip
  $('presetInfo').title = $('presetInfo').textContent;
}

/** The preset menu, built from the server's list (GET /v1/presets). */
export async function loadPresets() {
  try {
    app.presets = await app.api.json('GET', '/v1/presets');
  } catch (e) {
    app.presets = null; // an older server: its defaults, no menu
  }
  const list = app.presets ? app.presets.presets || [] : [];
  $('preset').replaceChildren(...list.map((p) => {
    const o = document.createElement('option');
    o.value = p.name;
    o.textContent = p.label || p.name;
    o.title = p.description || '';
    return o;
  }));
  $('preset').disabled = list.length === 0;
  $('stiffness').disabled = list.length === 0;
  if (list.length) {
    $('preset').value = list.some((p) => p.name === app.presets.default) ? app.presets.default : list[0].name;
    showAdvanced(currentPreset().params);
  }
  showStiffness();
  showPresetInfo();
}
