// Keyboard shortcuts (listed in the panel's help, `?` highlights it):
// Ctrl+Z undo, Ctrl+Shift+Z / Ctrl+Y redo, F frame the mesh, N/B/X/L/G
// tools (navigate, brush, box, lasso, fill), A apply constraints.

import { frameView, applyConstraints } from './app.js';
import { undo, redo } from './session.js';

export function attachKeys() {
  window.addEventListener('keydown', (e) => {
    const t = e.target;
    if (t && (t.tagName === 'INPUT' || t.tagName === 'SELECT' || t.tagName === 'TEXTAREA')) return;
    const key = e.key.toLowerCase();
    const ctrl = e.ctrlKey || e.metaKey;
    const tool = (v) => { const r = document.querySelector(`input[name=tool][value=${v}]`); if (r) r.checked = true; };
    if (ctrl && key === 'z' && !e.shiftKey) undo();
    else if (ctrl && (key === 'y' || (key === 'z' && e.shiftKey))) redo();
    else if (ctrl) return;
    else if (key === 'f') frameView();
    else if (key === 'n') tool('navigate');
    else if (key === 'b') tool('brush');
    else if (key === 'x') tool('box');
    else if (key === 'l') tool('lasso');
    else if (key === 'g') tool('fill');
    else if (key === 'a') applyConstraints();
    else if (key === '?') {
      document.getElementById('secHelp').open = true;
      document.querySelector('.help').classList.toggle('flash');
      document.getElementById('helpOverlay').hidden = false;
    }
    else return;
    e.preventDefault();
  });
}
