// report.html's case table: the filters, and a row's images shown in #viewer on a click (or from
// #case-<id>, a plot's point); needs sort.js before it.
const cases = document.getElementById('case-table');
function applyFilters() {
  const sel = Array.from(document.querySelectorAll('.filters select'));
  const text = document.getElementById('filter-text').value.toLowerCase();
  let shown = 0;
  for (const tr of cases.tBodies[0].rows) {
    const ok = sel.every(s => s.value === '' || tr.dataset[s.name] === s.value) &&
               (text === '' || tr.textContent.toLowerCase().includes(text));
    tr.hidden = !ok;
    shown += ok;
  }
  document.getElementById('shown').textContent = shown;
}
document.querySelectorAll('.filters select, #filter-text').forEach(e => {
  e.addEventListener('input', applyFilters); e.addEventListener('change', applyFilters); });

const viewer = document.getElementById('viewer');
cases.tBodies[0].addEventListener('click', ev => {
  const tr = ev.target.closest('tr');
  if (!tr) return;
  cases.querySelectorAll('tr.sel').forEach(r => r.classList.remove('sel'));
  tr.classList.add('sel');
  viewer.replaceChildren();
  const cap = document.createElement('p');
  cap.textContent = 'case ' + tr.dataset.case + ': ' + tr.dataset.label;
  viewer.appendChild(cap);
  if (tr.dataset.gif) {     // a motion case: its frames (display renders), shown at their pixel size
    const fig = document.createElement('figure');
    fig.className = 'motion';
    const box = document.createElement('div');
    box.className = 'wide';
    const img = document.createElement('img');
    img.src = tr.dataset.gif; img.alt = 'frames of case ' + tr.dataset.case;
    img.className = tr.dataset.gifkind === 'classes' ? 'frames classes' : 'frames';
    box.appendChild(img);
    fig.appendChild(box);
    const words = document.createElement('figcaption');
    words.textContent = tr.dataset.gifkind === 'classes' ?
      'each frame: its error classes, one pixel per camera pixel (the class images: [report] images = "errors", ' +
      'or a run that did not complete)' :
      'each frame: the error classes over the display render (N.L), the exact shading, the shading under the map';
    fig.appendChild(words);
    viewer.appendChild(fig);
    return;
  }
  if (!tr.dataset.err && !tr.dataset.shadow) {
    cap.textContent += ' (no images were written: [report] images = "none")';
    return;
  }
  const base = tr.dataset.nl || tr.dataset.shadow;
  if (tr.dataset.err && base) {     // the classes (nearest-neighbour) tinted over the scene's shading: shapes stay readable
    const fig = document.createElement('figure');
    const box = document.createElement('div');
    box.className = 'tint';
    for (const [src, alt] of [[base, 'shading'], [tr.dataset.err, 'error classes']]) {
      const img = document.createElement('img');
      img.src = src; img.alt = alt + ' (tinted) of case ' + tr.dataset.case;
      box.appendChild(img);
    }
    fig.appendChild(box);
    const cap = document.createElement('figcaption');
    cap.textContent = tr.dataset.nl ? 'error classes over the display render (N.L)'
                                    : 'error classes tinted over the shading';
    fig.appendChild(cap);
    viewer.appendChild(fig);
  }
  const shown = [[tr.dataset.exact, 'exact image', 'exact shading (display render, V*)'],
                 [tr.dataset.shadow, 'shadow image', 'shading under the shadow map (Lambert, ambient in shadow)'],
                 [tr.dataset.err, 'error image', 'error classes (colours beside)']];
  for (const [src, alt, words] of shown) {
    if (!src) continue;
    const fig = document.createElement('figure');
    const img = document.createElement('img');
    img.src = src; img.alt = alt + ' of case ' + tr.dataset.case; img.title = alt;
    fig.appendChild(img);
    const cap = document.createElement('figcaption');
    cap.textContent = words;
    fig.appendChild(cap);
    viewer.appendChild(fig);
  }
});
function showCase(id) {      // a plot's point: the case's row selected (filters cleared) and its images shown
  const tr = cases.querySelector('tbody tr[data-case="' + CSS.escape(id) + '"]');
  if (!tr) return;
  document.querySelectorAll('.filters select').forEach(s => s.value = '');
  document.getElementById('filter-text').value = '';
  applyFilters();
  tr.click();
  tr.scrollIntoView({block: 'nearest'});
  viewer.scrollIntoView({block: 'nearest'});
}
function fromHash() {
  const m = /^#case-(.+)$/.exec(decodeURIComponent(location.hash));
  if (m) showCase(m[1]);
}
window.addEventListener('hashchange', fromHash);
fromHash();
