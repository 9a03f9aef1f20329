// Every page's table.sortable: a click on a header sorts its rows by that column (th data-type=num:
// by value, a cell's data-v where it has one, undefined last in either direction; else alphabetically).
function cellValue(td, num) {
  const v = td.dataset.v !== undefined ? td.dataset.v : td.textContent;
  if (!num) return v;
  return v === '' || v === '-' ? NaN : parseFloat(v);
}
function sortBy(table, th) {
  const i = Array.from(th.parentNode.children).indexOf(th);
  const num = th.dataset.type === 'num';
  const asc = th.getAttribute('aria-sort') !== 'ascending';
  table.querySelectorAll('th').forEach(h => h.removeAttribute('aria-sort'));
  th.setAttribute('aria-sort', asc ? 'ascending' : 'descending');
  const body = table.tBodies[0];
  const rows = Array.from(body.rows);
  rows.sort((a, b) => {
    const x = cellValue(a.cells[i], num), y = cellValue(b.cells[i], num);
    if (num) {                      // undefined values (NaN) last, in either direction
      if (isNaN(x) || isNaN(y)) return isNaN(x) - isNaN(y);
      return asc ? x - y : y - x;
    }
    return asc ? x.localeCompare(y) : y.localeCompare(x);
  });
  const frag = document.createDocumentFragment();
  rows.forEach(r => frag.appendChild(r));
  body.appendChild(frag);
}
document.querySelectorAll('table.sortable').forEach(t =>
  t.querySelectorAll('thead th').forEach(th => th.addEventListener('click', () => sortBy(t, th))));
