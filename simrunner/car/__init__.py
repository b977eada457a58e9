"""The car model: the dartpy multibody (``body``, ``physics``) and the effects catalogue
(``effects``) that adds what the nominal model leaves out."""
