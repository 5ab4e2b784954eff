"""Topological terrain evolution on 3-G-maps (topological-gmaps-evolution).

Bezin, Crespin, Skapin, Terraz, Meseure: *Topological Operations for
Geomorphological Evolution*. A terrain is a set of material volumes stored in a
3-generalized map; vertex displacements change it through atomic topological
operations that keep the map valid.

==================  ==========================================================
module              holds
==================  ==========================================================
``gmap``            the 3-G-map kernel: int32 dart arrays (20 bytes a dart),
                    orbits, sewing, cell insertion/removal/contraction, check
``builders``        maps from polyhedra; layered boxes on a lattice
``geometry``        orientation, polygon triangulation, segment–face tests
``operations``      the atomic operations (§3.2–3.5)
``face_collapse``   a vertex landing on a face it is joined to (Fig. 7b/c, 8)
``events``          the event priority queue with re-injection (§3.1)
``scenarios``       arch, drilling and cavern, seeded
``export``          a triangle mesh per volume with its material (PLY, glTF)
``checks``          volumes and self-intersection tests
``command``         ``arches-render evolve``
``benchmarks``      bytes per dart, events per second
==================  ==========================================================
"""
