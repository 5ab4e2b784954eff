"""Materials: the ``triplanar`` blended BSDF plugin, its presets and bundled textures."""
