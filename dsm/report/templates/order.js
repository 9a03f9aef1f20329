// A contender's cards ordered by a data attribute (a button's data-key), undefined values last, ties in
// the suite's order.
function orderBy(key) {
  const box = document.getElementById('cards');
  const cards = Array.from(box.children);
  const v = c => c.dataset[key] === '' ? NaN : parseFloat(c.dataset[key]);
  cards.sort((a, b) => {
    const x = v(a), y = v(b);
    if (isNaN(x) !== isNaN(y)) return isNaN(x) ? 1 : -1;
    const d = key === 'suite' ? x - y : y - x;
    return (isNaN(d) || d === 0) ? a.dataset.suite - b.dataset.suite : d;
  });
  cards.forEach(c => box.appendChild(c));
  document.querySelectorAll('.order button').forEach(b => b.setAttribute('aria-pressed', b.dataset.key === key));
}
document.querySelectorAll('.order button').forEach(b => b.addEventListener('click', () => orderBy(b.dataset.key)));
