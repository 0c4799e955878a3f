"""Pictures: the reachable sets back-ends computed (:mod:`.reach_sets`), with the requirements
drawn from the properties (:mod:`.requirements`) on axes with units (:mod:`.axes`), and why a
back-end of which nothing is drawn kept no sets (:mod:`.missing`). Run plots,
abort maps and subdomain maps of the benchmark runner are in :mod:`reach.bench.plots`."""
