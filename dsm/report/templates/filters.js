// The leaderboard's filters: a row is shown when every chosen value equals its data attribute of that
// name (a table whose rows lack the attribute ignores that filter); a click on a ranking row chooses
// its contender in the cases table.
const selects = Array.from(document.querySelectorAll('.filters select'));
function applyFilters() {
  for (const table of document.querySelectorAll('table.filtered')) {
    let shown = 0;
    for (const tr of table.tBodies[0].rows) {
      const ok = selects.every(s => s.value === '' || tr.dataset[s.name] === undefined ||
                                    tr.dataset[s.name] === s.value);
      tr.hidden = !ok;
      shown += ok;
    }
    const count = document.getElementById(table.id + '-shown');
    if (count) count.textContent = shown;
  }
}
selects.forEach(s => s.addEventListener('change', applyFilters));
document.querySelectorAll('#ranking tbody tr').forEach(tr => tr.addEventListener('click', e => {
  if (e.target.closest('a')) return;          // the contender's name opens its page
  document.querySelector('.filters select[name=contender]').value = tr.dataset.contender;
  applyFilters();
  document.getElementById('cases').scrollIntoView();
}));
