// A click on a figure (.plots img) shows it enlarged (1.5 times its pixel size) over the page; a
// second click closes it.
const zoom = document.getElementById('zoom');
if (zoom) {
  document.querySelectorAll('.plots img').forEach(img => img.addEventListener('click', () => {
    const big = zoom.querySelector('img');
    big.src = img.src; big.alt = img.alt + ' (enlarged)';
    big.style.width = (img.naturalWidth * 1.5) + 'px';
    zoom.style.display = 'block';
  }));
  zoom.addEventListener('click', () => { zoom.style.display = 'none'; });
}
