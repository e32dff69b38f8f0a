// Colours of the view: the painted regions per face (a face takes its
// vertices' label when all three agree; a face whose vertices disagree is
// MIXED and drawn hatched, so a single stray constrained vertex shows as a
// hatched ring of faces), or a per-vertex colour map of a curvature field.

export const FREE = 0;
export const FIXED = -1; // labels: 0 free, -1 fixed, k + 1 handle k
/** Face label of a face whose vertices carry different labels. */
export const MIXED = -2;

const HANDLE_COLORS = [[0.15, 0.35, 0.95], [0.2, 0.6, 1.0], [0.45, 0.25, 0.95], [0.1, 0.75, 0.85]];
const MIXED_COLOR = [0.98, 0.8, 0.15];

/** The colour of a region label. */
export function labelColor(l) {
  if (l === FIXED) return [0.9, 0.15, 0.12];
  if (l === MIXED) return MIXED_COLOR;
  return l > 0 ? HANDLE_COLORS[(l - 1) % HANDLE_COLORS.length] : [0.55, 0.8, 0.5];
}

/** Per-face labels (Int32Array, one per triangle) of the vertex labels. */
export function faceLabels(labels, triangles) {
  const out = new Int32Array(triangles.length / 3);
  for (let f = 0; f < out.length; f++) {
    const a = labels[triangles[3 * f]], b = labels[triangles[3 * f + 1]], c = labels[triangles[3 * f + 2]];
    out[f] = a === b && b === c ? a : MIXED;
  }
  return out;
}

/** Over a texture, the share of a painted region's colour (a tint: the
 * texture still shows through); free faces show the texture alone. */
export const REGION_TINT = 0.55;

/** Face colours (vec3 per face), hatch flags and texture tints of
 * per-face labels. */
export function faceColors(faces) {
  const rgb = new Float32Array(3 * faces.length);
  const hatch = new Float32Array(faces.length);
  const tint = new Float32Array(faces.length);
  for (let f = 0; f < faces.length; f++) {
    rgb.set(labelColor(faces[f]), 3 * f);
    hatch[f] = faces[f] === MIXED ? 1 : 0;
    tint[f] = faces[f] === FREE ? 0 : REGION_TINT;
  }
  return { rgb, hatch, tint };
}

/** Diverging colour of `t` in [-1, 1]: blue, white, red. */
function diverging(t) {
  const s = Math.max(-1, Math.min(1, t));
  return s < 0 ? [1 + 0.8 * s, 1 + 0.6 * s, 1] : [1, 1 - 0.6 * s, 1 - 0.8 * s];
}

/** Per-vertex colours of a scalar field into `out` (vec3 per vertex), on a
 * symmetric range: the 95th percentile of |value| (outliers saturate). */
export function fieldColors(field, out) {
  const mags = field.map(Math.abs).sort((a, b) => a - b);
  const range = Math.max(mags[Math.floor(0.95 * (mags.length - 1))], 1e-12);
  for (let i = 0; i < field.length; i++) out.set(diverging(field[i] / range), 3 * i);
  return out;
}
