"""``arches-render preview``: a local web page that shows a progressive render of a scene
file and renders it again on every save (:mod:`.session` renders, :mod:`.server` serves)."""
