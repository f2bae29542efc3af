// cortex inspect: the page. Plain JS, no libraries. State is one map of nodes and one of edges, replaced by
// snapshots and updated by patches (latest value per element), so memory stays bounded by the graph's size.
'use strict';

const S = { nodes: new Map(), edges: new Map(), world: { poses: {}, scans: {}, ellipses: {} }, selected: null,
  config: { allow_edit: false, debug: false }, seq: 0, patches: 0, structureDirty: true, worldDirty: true,
  treeOpen: new Set(), imageShown: new Map(), expanded: new Map(), debug: null, debugImage: new Image(), debugImageUrl: '' };
const $ = (id) => document.getElementById(id);
const SVG = 'http://www.w3.org/2000/svg';
const TYPE_COLORS = ['#3d6bd6', '#2e9e6a', '#d9822b', '#8e5cc9', '#c0392b', '#16a2b8', '#7a8a1e', '#b5487a', '#5d6d7e'];
const typeColor = (t) => { let h = 0; for (const c of t) h = (h * 31 + c.charCodeAt(0)) >>> 0; return TYPE_COLORS[h % TYPE_COLORS.length]; };
const el = (tag, attrs = {}, text) => { const e = document.createElement(tag); for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v); if (text !== undefined) e.textContent = text; return e; };
const sel = (tag, attrs = {}) => { const e = document.createElementNS(SVG, tag); for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v); return e; };
const num = (x) => (typeof x === 'number' ? (Number.isInteger(x) ? String(x) : String(+x.toPrecision(6))) : String(x));

function fmtValue(v) {
  if ('v' in v) return Array.isArray(v.v) ? '[' + v.v.map(num).join(', ') + ']' : (v.cut ? v.v + '… (' + v.cut + ' chars)' : num(v.v));
  if (v.image) return 'image ' + v.image[0] + '×' + v.image[1] + ' (' + v.len + ' bytes)';
  if (v.t === 'bytes') return v.len + ' bytes';
  return 'len ' + v.len + ', min ' + num(v.min) + ', max ' + num(v.max) + ', [' + v.head.map(num).join(', ') + ', …]';
}

function imgUrl(nodeId, name) { return '/api/image?node=' + nodeId + '&attr=' + encodeURIComponent(name) + '&v=' + S.seq; }

// Pictures refresh at most once a second each, reusing one <img> element.
function refreshImage(img, nodeId, name) {
  const key = nodeId + '/' + name; const now = Date.now();
  if (now - (S.imageShown.get(key) || 0) < 1000 && img.src) return;
  S.imageShown.set(key, now); img.src = imgUrl(nodeId, name);
}

function valueCell(key, name, v, nodeId) {
  const td = el('td');
  const span = el('span', { class: 'val', 'data-attr': name }, fmtValue(v)); td.append(span);
  if (v.image && nodeId) { const img = el('img', { width: 240 }); td.append(img); refreshImage(img, nodeId, name); }
  if (v.len !== undefined && !v.image && v.t !== 'bytes') {
    const b = el('button', { class: 'small' }, S.expanded.has(key + '/' + name) ? 'collapse' : 'expand');
    b.onclick = async () => {
      const k = key + '/' + name;
      if (S.expanded.has(k)) { S.expanded.delete(k); renderPanel(); return; }
      const r = await fetch('/api/attr?el=' + encodeURIComponent(key) + '&name=' + encodeURIComponent(name));
      const j = await r.json(); S.expanded.set(k, r.ok ? j.v.map(num).join(', ') : j.error); renderPanel();
    };
    td.append(' ', b);
    if (S.expanded.has(key + '/' + name)) td.append(el('div', { class: 'hint' }, S.expanded.get(key + '/' + name)));
  }
  return td;
}

async function post(url, body, errBox) {
  errBox.textContent = '';
  try {
    const r = await fetch(url, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
    const j = await r.json();
    if (!r.ok) { errBox.textContent = j.error || ('HTTP ' + r.status); return null; }
    return j;
  } catch (e) { errBox.textContent = String(e); return null; }
}

function renderPanel() {
  const body = $('sel-body'); body.textContent = ''; body.className = '';
  const key = S.selected; const item = key && (key.startsWith('n:') ? S.nodes.get(key.slice(2)) : S.edges.get(key));
  if (!item) { $('sel-title').textContent = key ? key + ' (gone)' : 'Nothing selected'; return; }
  const isNode = key.startsWith('n:');
  $('sel-title').textContent = isNode ? item.name + ' · ' + item.type + ' · id ' + item.id
    : (S.nodes.get(item.from) || { name: item.from }).name + ' —' + item.type + '→ ' + (S.nodes.get(item.to) || { name: item.to }).name;
  const table = el('table', { class: 'attrs', id: 'attr-table' });
  for (const name of Object.keys(item.attrs).sort()) {
    const v = item.attrs[name];
    const tr = el('tr', { 'data-attr-row': name });
    tr.append(el('td', { class: 'k' }, name), valueCell(key, name, v, isNode ? item.id : null), el('td', { class: 't' }, v.t));
    if (S.config.allow_edit && v.t !== 'bytes') {
      const td = el('td'); const input = el('input', { size: 8, 'data-edit': name });
      input.value = 'v' in v ? (Array.isArray(v.v) ? v.v.join(', ') : String(v.v)) : '';
      const set = el('button', { class: 'small' }, 'set');
      set.onclick = () => post('/api/edit', { op: 'set_attr', element: key, name, value: input.value }, $('edit-error'));
      const rm = el('button', { class: 'small' }, '×');
      rm.onclick = () => post('/api/edit', { op: 'remove_attr', element: key, name }, $('edit-error'));
      td.append(input, set, rm); tr.append(td);
    }
    table.append(tr);
  }
  body.append(table);
  if (S.config.allow_edit) {
    const f = el('form'); const n = el('input', { placeholder: 'new attribute', size: 10 }); const t = el('input', { placeholder: 'type if new', size: 7 });
    const v = el('input', { placeholder: 'value', size: 8 });
    f.append(n, t, v, el('button', {}, 'add'));
    f.onsubmit = (e) => { e.preventDefault(); post('/api/edit', { op: 'set_attr', element: key, name: n.value, value: v.value, ...(t.value ? { type: t.value } : {}) }, $('edit-error')); };
    const del = el('button', {}, isNode ? 'delete node' : 'delete edge');
    del.onclick = () => post('/api/edit', isNode ? { op: 'delete_node', id: item.id } : { op: 'delete_edge', element: key }, $('edit-error'));
    body.append(f, del);
  }
}

function select(key) {
  S.selected = key;
  document.querySelectorAll('#graph .selected').forEach((e) => e.classList.remove('selected'));
  const g = document.querySelector('#graph [data-key="' + CSS.escape(key) + '"]'); if (g) g.classList.add('selected');
  renderPanel();
}

// ---- Graph view: RT forest laid out left to right; other edges drawn as dashed curves with their type.
function rtChildren() {
  const children = new Map(); const parent = new Map();
  for (const e of S.edges.values()) {
    if (e.type !== 'RT' || !S.nodes.has(e.from) || !S.nodes.has(e.to) || parent.has(e.to)) continue;
    parent.set(e.to, e.from); if (!children.has(e.from)) children.set(e.from, []); children.get(e.from).push(e.to);
  }
  for (const list of children.values()) list.sort((a, b) => (S.nodes.get(a).name < S.nodes.get(b).name ? -1 : 1));
  const roots = [...S.nodes.keys()].filter((id) => !parent.has(id))
    .sort((a, b) => (children.has(b) ? 1 : 0) - (children.has(a) ? 1 : 0) || (S.nodes.get(a).name < S.nodes.get(b).name ? -1 : 1));
  return { children, roots };
}

const POS = new Map();
function layout() {
  POS.clear(); const { children, roots } = rtChildren(); let slot = 0; const seen = new Set();
  const place = (id, depth) => {
    if (seen.has(id)) return 0; seen.add(id);
    const kids = (children.get(id) || []).filter((k) => !seen.has(k));
    let y;
    if (kids.length === 0) { y = slot++ * 34; } else { const ys = kids.map((k) => place(k, depth + 1)); y = (ys[0] + ys[ys.length - 1]) / 2; }
    POS.set(id, { x: depth * 200, y }); return y;
  };
  for (const r of roots) { if (children.has(r)) { place(r, 0); slot += 0.5; } }
  // Lone nodes (no RT edge): a grid below the forest.
  const lone = roots.filter((r) => !children.has(r)); const base = slot * 34 + 40;
  lone.forEach((id, i) => POS.set(id, { x: (i % 6) * 200, y: base + Math.floor(i / 6) * 34 }));
}

function drawGraph() {
  layout(); const nodesG = $('nodes'); const edgesG = $('edges'); nodesG.textContent = ''; edgesG.textContent = '';
  for (const e of S.edges.values()) {
    const a = POS.get(e.from); const b = POS.get(e.to); if (!a || !b) continue;
    const rt = e.type === 'RT'; const g = sel('g', { class: 'edge ' + (rt ? 'rt' : 'other'), 'data-key': e.key });
    const x1 = a.x + 150, y1 = a.y + 12, x2 = b.x, y2 = b.y + 12;
    const d = rt ? `M${x1},${y1} C${x1 + 25},${y1} ${x2 - 25},${y2} ${x2},${y2}`
      : `M${a.x + 75},${a.y + 24} Q${(a.x + b.x) / 2 + 110},${(a.y + b.y) / 2 + 12} ${b.x + 75},${b.y}`;
    g.append(sel('path', { d }), sel('path', { d, class: 'hit' }));
    if (!rt) { const t = sel('text', { x: (a.x + b.x) / 2 + 130, y: (a.y + b.y) / 2 + 14 }); t.textContent = e.type; g.append(t); }
    g.onclick = (ev) => { ev.stopPropagation(); select(e.key); };
    edgesG.append(g);
  }
  for (const n of S.nodes.values()) {
    const p = POS.get(n.id); if (!p) continue;
    const g = sel('g', { class: 'node', transform: `translate(${p.x},${p.y})`, 'data-key': 'n:' + n.id });
    g.append(sel('rect', { width: 150, height: 25, stroke: typeColor(n.type) }));
    const t = sel('text', { x: 6, y: 11 }); t.textContent = n.name.length > 24 ? n.name.slice(0, 23) + '…' : n.name;
    const ty = sel('text', { x: 6, y: 21, class: 'type' }); ty.textContent = n.type;
    g.append(t, ty); g.onclick = (ev) => { ev.stopPropagation(); select('n:' + n.id); };
    nodesG.append(g);
  }
  $('graph-count').textContent = S.nodes.size + ' nodes, ' + S.edges.size + ' edges';
  if (S.selected) { const g = document.querySelector('#graph [data-key="' + CSS.escape(S.selected) + '"]'); if (g) g.classList.add('selected'); }
}

const VIEW = { x: 20, y: 20, k: 1 };
function applyView() { $('graph-root').setAttribute('transform', `translate(${VIEW.x},${VIEW.y}) scale(${VIEW.k})`); }
function fit() {
  const svg = $('graph'); const w = svg.clientWidth || 900; const h = svg.clientHeight || 600;
  let maxX = 0, maxY = 0; for (const p of POS.values()) { maxX = Math.max(maxX, p.x + 160); maxY = Math.max(maxY, p.y + 30); }
  VIEW.k = Math.min(1.2, Math.max(0.1, Math.min(w / (maxX + 40), h / (maxY + 40)))); VIEW.x = 20; VIEW.y = 20; applyView();
}
(function panZoom() {
  const svg = $('graph'); let drag = null;
  svg.addEventListener('wheel', (e) => { e.preventDefault(); const f = e.deltaY < 0 ? 1.15 : 1 / 1.15; const r = svg.getBoundingClientRect();
    const mx = e.clientX - r.left, my = e.clientY - r.top; VIEW.x = mx - (mx - VIEW.x) * f; VIEW.y = my - (my - VIEW.y) * f; VIEW.k *= f; applyView(); }, { passive: false });
  svg.addEventListener('mousedown', (e) => { drag = { x: e.clientX - VIEW.x, y: e.clientY - VIEW.y }; });
  window.addEventListener('mousemove', (e) => { if (drag) { VIEW.x = e.clientX - drag.x; VIEW.y = e.clientY - drag.y; applyView(); } });
  window.addEventListener('mouseup', () => { drag = null; });
  $('fit').onclick = fit;
})();

function flash(key) {
  const g = document.querySelector('#graph [data-key="' + CSS.escape(key) + '"]');
  if (g) { g.classList.remove('flash'); void g.getBoundingClientRect(); g.classList.add('flash'); }
  const row = document.getElementById('tree-' + key);
  if (row) { row.classList.remove('flash-row'); void row.offsetWidth; row.classList.add('flash-row'); }
}

// ---- Tree view: the RT hierarchy, collapsible, attributes under each node.
function treeAttrs(n) {
  const box = el('div', { id: 'tree-attrs-' + n.id });
  for (const name of Object.keys(n.attrs).sort()) {
    const v = n.attrs[name]; const line = el('div', { class: 'attrline' });
    line.append(el('span', { class: 'k' }, name), ': ', fmtValue(v));
    if (v.image) { const img = el('img', { 'data-node': n.id, 'data-attr': name }); line.append(img); refreshImage(img, n.id, name); }
    box.append(line);
  }
  return box;
}
function drawTree() {
  const root = $('tree'); root.textContent = ''; const { children, roots } = rtChildren(); const seen = new Set();
  const item = (id, depth) => {
    if (seen.has(id)) return el('div'); seen.add(id); const n = S.nodes.get(id);
    const d = el('details', { id: 'tree-n:' + id }); if (S.treeOpen.has(id) || (depth < 2 && !S.treeOpen.has('closed:' + id))) d.open = true;
    d.addEventListener('toggle', () => { if (d.open) { S.treeOpen.add(id); S.treeOpen.delete('closed:' + id); } else { S.treeOpen.delete(id); S.treeOpen.add('closed:' + id); } });
    const s = el('summary'); s.append(el('b', {}, n.name), ' ', el('span', { class: 'type' }, n.type + ' #' + id));
    d.append(s, treeAttrs(n)); for (const k of children.get(id) || []) d.append(item(k, depth + 1)); return d;
  };
  for (const r of roots) root.append(item(r, 0));
}
function updateTreeNode(n) {
  const box = document.getElementById('tree-attrs-' + n.id); if (box) box.replaceWith(treeAttrs(n));
}

// ---- 2D world: top view of the largest RT tree (mm in the graph, drawn in metres).
function drawWorld() {
  const c = $('world'); const g = c.getContext('2d'); g.clearRect(0, 0, c.width, c.height);
  const poses = S.world.poses || {}; const byRoot = new Map();
  for (const [id, p] of Object.entries(poses)) byRoot.set(p[4], (byRoot.get(p[4]) || 0) + 1);
  const root = [...byRoot.entries()].sort((a, b) => b[1] - a[1])[0]?.[0];
  const ids = Object.keys(poses).filter((id) => poses[id][4] === root);
  // Top view: the "up" axis is the one along which the poses spread least (CORTEX world graphs are y-up).
  const spread = [0, 1, 2].map((a) => { const v = ids.map((id) => poses[id][a]); return v.length ? Math.max(...v) - Math.min(...v) : 0; });
  const up = spread.indexOf(Math.min(...spread)); const [ax, ay] = up === 2 ? [0, 1] : up === 1 ? [0, 2] : [1, 2];
  let minX = Infinity, minY = Infinity, maxX = -Infinity, maxY = -Infinity;
  const grow = (x, y) => { minX = Math.min(minX, x); maxX = Math.max(maxX, x); minY = Math.min(minY, y); maxY = Math.max(maxY, y); };
  for (const id of ids) grow(poses[id][ax], poses[id][ay]);
  for (const [id, pts] of Object.entries(S.world.scans || {})) if (ids.includes(id)) for (const p of pts) grow(p[ax], p[ay]);
  if (!isFinite(minX)) { $('world-info').textContent = 'no geometric nodes'; return; }
  const pad = 500; minX -= pad; minY -= pad; maxX += pad; maxY += pad;
  const k = Math.min(c.width / (maxX - minX), c.height / (maxY - minY));
  const X = (x) => (x - minX) * k, Y = (y) => c.height - (y - minY) * k;
  g.strokeStyle = '#eef0f3'; g.lineWidth = 1;
  const step = Math.pow(10, Math.ceil(Math.log10((maxX - minX) / 20)));
  for (let x = Math.ceil(minX / step) * step; x < maxX; x += step) { g.beginPath(); g.moveTo(X(x), 0); g.lineTo(X(x), c.height); g.stroke(); }
  for (let y = Math.ceil(minY / step) * step; y < maxY; y += step) { g.beginPath(); g.moveTo(0, Y(y)); g.lineTo(c.width, Y(y)); g.stroke(); }
  g.fillStyle = '#2e9e6a';
  for (const [id, pts] of Object.entries(S.world.scans || {})) if (ids.includes(id)) for (const p of pts) g.fillRect(X(p[ax]) - 1, Y(p[ay]) - 1, 2, 2);
  for (const [id, cov] of Object.entries(S.world.ellipses || {})) {
    const p = poses[id]; if (!p || up !== 2) continue;
    const [a, b, d] = cov; const tr = (a + d) / 2, det = Math.sqrt(Math.max(0, ((a - d) / 2) ** 2 + b * b));
    const l1 = tr + det, l2 = Math.max(0, tr - det), ang = 0.5 * Math.atan2(2 * b, a - d);
    g.strokeStyle = '#c0392b'; g.beginPath(); g.ellipse(X(p[0]), Y(p[1]), Math.max(2, 2 * Math.sqrt(l1) * k), Math.max(2, 2 * Math.sqrt(l2) * k), -ang, 0, 2 * Math.PI); g.stroke();
  }
  g.font = '10px system-ui'; g.textBaseline = 'middle';
  for (const id of ids) {
    const p = poses[id]; const n = S.nodes.get(id); if (!n) continue; const x = X(p[ax]), y = Y(p[ay]);
    if (n.type === 'gaze_target') { g.strokeStyle = '#e0245e'; g.lineWidth = 2; g.beginPath(); g.arc(x, y, 8, 0, 7); g.moveTo(x - 12, y); g.lineTo(x + 12, y); g.moveTo(x, y - 12); g.lineTo(x, y + 12); g.stroke(); g.lineWidth = 1; g.fillStyle = '#e0245e'; g.fillText('attention target', x + 12, y - 10); continue; }
    g.fillStyle = typeColor(n.type); g.strokeStyle = g.fillStyle;
    g.beginPath(); g.arc(x, y, 3.5, 0, 7); g.fill();
    if (up === 2) { g.beginPath(); g.moveTo(x, y); g.lineTo(x + 12 * Math.cos(p[3]), y - 12 * Math.sin(p[3])); g.stroke(); }
    g.fillStyle = '#1d2330'; g.fillText(n.name, x + 6, y);
  }
  $('world-info').textContent = ids.length + ' geometric nodes under ' + (S.nodes.get(root)?.name || root) + ' · grid ' + (step / 1000) + ' m · plane ' + 'xyz'[ax] + 'xyz'[ay];
}

// ---- Debug view.
function drawDebug() {
  const d = S.debug; if (!d) return;
  $('debug-error').textContent = !d.available ? 'No BICA runtime is connected to this inspector (start it with --demo to see one).' : (d.error || d.components?.error || '');
  if (!d.available) return;
  if (Array.isArray(d.components)) {
    const tb = document.querySelector('#components tbody'); tb.textContent = '';
    for (const c of d.components) {
      const tr = el('tr'); const cb = el('input', { type: 'checkbox' }); cb.checked = c.marked;
      cb.onchange = () => post('/api/debug/mark', { component: c.name, on: cb.checked }, $('debug-error'));
      const td = el('td'); td.append(cb);
      tr.append(td, el('td', { title: c.name }, c.name.replace(/\b[a-z_0-9]+::/g, '')), el('td', {}, c.active ? 'yes' : ''), el('td', {}, c.nominal_hz.toFixed(1)),
        el('td', {}, c.achieved_hz.toFixed(1)), el('td', {}, c.runs), el('td', {}, c.misses), el('td', {}, c.skipped));
      tb.append(tr);
    }
  }
  if (d.frame) S.frame = d.frame;
  const f = S.frame; if (!f) return;
  const by = { Image: [], Robot: [], World: [] }; for (const e of f.entries) by[e.primitive.frame]?.push(e.primitive);
  const img = by.Image.find((p) => p.shape.Image);
  const drawImageSpace = () => {
    const c = $('dbg-image'); const g = c.getContext('2d'); g.clearRect(0, 0, c.width, c.height);
    const w = img ? img.shape.Image.width_px : 640, h = img ? img.shape.Image.height_px : 480; const k = Math.min(c.width / w, c.height / h);
    if (img && S.debugImage.complete && S.debugImage.naturalWidth) g.drawImage(S.debugImage, 0, 0, S.debugImage.naturalWidth * k, S.debugImage.naturalHeight * k);
    drawPrims(g, by.Image.filter((p) => !p.shape.Image), (x) => x * k, (y) => y * k, k);
  };
  if (img && img.shape.Image.url !== S.debugImageUrl) { S.debugImageUrl = img.shape.Image.url; S.debugImage.onload = drawImageSpace; S.debugImage.src = img.shape.Image.url; }
  drawImageSpace();
  for (const [space, id, forward] of [['Robot', 'dbg-robot', true], ['World', 'dbg-world', false]]) {
    const c = $(id); const g = c.getContext('2d'); g.clearRect(0, 0, c.width, c.height); const prims = by[space];
    let ext = 2; for (const p of prims) for (const v of Object.values(p.shape)[0] ? Object.values(Object.values(p.shape)[0]) : []) if (v && typeof v.x === 'number') ext = Math.max(ext, Math.abs(v.x) * 1.2, Math.abs(v.y) * 1.2);
    const k = c.width / (2 * ext);
    // Robot frame: x forward drawn up, y left drawn left. World: x right, y up.
    const X = forward ? (x, y) => c.width / 2 - y * k : (x) => c.width / 2 + x * k;
    const Y = forward ? (x) => c.height / 2 - x * k : (x, y) => c.height / 2 - y * k;
    g.strokeStyle = '#eef0f3'; g.beginPath(); g.moveTo(c.width / 2, 0); g.lineTo(c.width / 2, c.height); g.moveTo(0, c.height / 2); g.lineTo(c.width, c.height / 2); g.stroke();
    drawPrims(g, prims, (x, y) => X(x, y), (x, y) => Y(x, y), k);
  }
}
function drawPrims(g, prims, X, Y, k) {
  g.font = '11px system-ui';
  for (const p of prims) {
    const [kind, s] = Object.entries(p.shape)[0]; const c = p.color; g.strokeStyle = g.fillStyle = `rgba(${c.r},${c.g},${c.b},${c.a / 255})`; g.lineWidth = 1.5;
    const P = (q) => [X(q.x, q.y), Y(q.x, q.y)]; g.beginPath();
    if (kind === 'Point') { const [x, y] = P(s.at); g.fillRect(x - 2, y - 2, 4, 4); }
    else if (kind === 'Line' || kind === 'Arrow') { const [x1, y1] = P(s.from), [x2, y2] = P(s.to); g.moveTo(x1, y1); g.lineTo(x2, y2);
      if (kind === 'Arrow') { const a = Math.atan2(y2 - y1, x2 - x1); g.moveTo(x2, y2); g.lineTo(x2 - 8 * Math.cos(a - 0.4), y2 - 8 * Math.sin(a - 0.4)); g.moveTo(x2, y2); g.lineTo(x2 - 8 * Math.cos(a + 0.4), y2 - 8 * Math.sin(a + 0.4)); } g.stroke(); }
    else if (kind === 'Circle') { const [x, y] = P(s.center); g.arc(x, y, Math.max(1, s.radius * k), 0, 7); g.stroke(); }
    else if (kind === 'Ellipse') { const [x, y] = P(s.center); g.ellipse(x, y, Math.max(1, s.radius_x * k), Math.max(1, s.radius_y * k), -s.rotation_rad, 0, 7); g.stroke(); }
    else if (kind === 'Rectangle') { const [x1, y1] = P(s.min), [x2, y2] = P(s.max); g.strokeRect(Math.min(x1, x2), Math.min(y1, y2), Math.abs(x2 - x1), Math.abs(y2 - y1)); }
    else if (kind === 'Box3') { const [x, y] = P({ x: s.center[0], y: s.center[1] }); g.save(); g.translate(x, y); g.rotate(-s.yaw_rad); g.strokeRect(-s.size[0] * k / 2, -s.size[1] * k / 2, s.size[0] * k, s.size[1] * k); g.restore(); }
    else if (kind === 'Text') { const [x, y] = P(s.at); g.fillText(s.text, x, y); }
  }
}

// ---- Updates.
let frameQueued = false;
function render() {
  if (frameQueued) return; frameQueued = true;
  requestAnimationFrame(() => {
    frameQueued = false;
    if (S.structureDirty) { drawGraph(); drawTree(); S.structureDirty = false; }
    if (S.worldDirty) { drawWorld(); S.worldDirty = false; }
  });
}
function onSnapshot(s) {
  S.nodes.clear(); S.edges.clear(); S.seq = s.seq;
  for (const n of s.nodes) S.nodes.set(n.id, n);
  for (const e of s.edges) S.edges.set(e.key, e);
  S.world = s.world; const first = POS.size === 0; S.structureDirty = true; S.worldDirty = true; render();
  if (first) requestAnimationFrame(() => requestAnimationFrame(fit));
  renderPanel();
}
function onPatch(p) {
  S.seq = p.seq; S.patches++; let structure = false; const touched = [];
  for (const id of p.deleted_nodes) { S.nodes.delete(id); structure = true; for (const [k, e] of S.edges) if (e.from === id || e.to === id) S.edges.delete(k); }
  for (const k of p.deleted_edges) { S.edges.delete(k); structure = true; }
  for (const n of p.nodes) { const old = S.nodes.get(n.id); if (!old || old.name !== n.name) structure = true; S.nodes.set(n.id, n); touched.push('n:' + n.id); if (old && !structure) updateTreeNode(n); }
  for (const e of p.edges) { if (!S.edges.has(e.key)) structure = true; S.edges.set(e.key, e); touched.push(e.key); }
  if (p.world) { S.world = p.world; S.worldDirty = true; }
  if (structure) S.structureDirty = true;
  render();
  requestAnimationFrame(() => touched.forEach(flash));
  if (S.selected && (touched.includes(S.selected) || structure)) renderPanel();
}

async function start() {
  try { S.config = await (await fetch('/api/config')).json(); } catch (e) { /* defaults */ }
  $('title').textContent = S.config.title || 'cortex inspect';
  $('edit-box').hidden = !S.config.allow_edit;
  document.querySelectorAll('#tabs button').forEach((b) => (b.onclick = () => {
    document.querySelectorAll('#tabs button, .view').forEach((e) => e.classList.remove('on'));
    b.classList.add('on'); $('view-' + b.dataset.view).classList.add('on');
    if (b.dataset.view === 'world') { S.worldDirty = true; render(); } if (b.dataset.view === 'debug') drawDebug();
    if (b.dataset.view === 'graph') fit();
  }));
  $('graph').addEventListener('click', () => {});
  $('new-node').onsubmit = async (e) => { e.preventDefault(); const f = e.target;
    const r = await post('/api/edit', { op: 'insert_node', node_type: f.node_type.value, name: f.name.value }, $('edit-error')); if (r && r.id) select('n:' + r.id); };
  $('new-edge').onsubmit = (e) => { e.preventDefault(); const f = e.target;
    post('/api/edit', { op: 'insert_edge', from: f.from.value, to: f.to.value, edge_type: f.edge_type.value }, $('edit-error')); };
  const es = new EventSource('/api/events');
  es.addEventListener('snapshot', (m) => onSnapshot(JSON.parse(m.data)));
  es.addEventListener('patch', (m) => onPatch(JSON.parse(m.data)));
  es.addEventListener('debug', (m) => { S.debug = JSON.parse(m.data); if ($('view-debug').classList.contains('on')) drawDebug(); });
  es.addEventListener('status', (m) => { const s = JSON.parse(m.data); const a = s.agent;
    $('status').textContent = `${a.agent} · graph ${a.graph || '(joining)'}` + (a.foreign_refused ? ` · ${a.foreign_refused} foreign refused` : '') + ` · ${a.ready ? 'ready' : 'joining'} · ${a.nodes} nodes, ${a.edges} edges · peers ${a.peers.length} · ` +
      `${S.patches} patches · coalesced ${s.stream ? s.stream.coalesced : 0} · resyncs ${s.stream ? s.stream.resyncs : 0}` + (S.config.allow_edit ? ' · editing on' : ' · read-only'); });
  es.onerror = () => { $('status').textContent = 'disconnected — retrying…'; };
  window.inspector = S;
}
start();
