"""Screen-space contact shadows: the march (dsm.contact.march) and the engines' presets."""
