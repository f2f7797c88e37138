"""Discovery: when no catalogued effect explains the data, find the missing term and name its physics.

Split along the method's steps (PySINDy's library/optimizer split, run by simulation rather than on
derivatives: the measured states are too noisy for derivative-based regression at these noise levels):

* ``library``: the candidate terms as the fit sees them (:class:`~.library.Library`), derived from the
  physics' one term table ``fmu_src.terms.TERMS`` (every term in the force balance, the coil equation or a
  reading, with its units and physical reading); a term is fitted as its coefficient relative to its natural
  scale (and the time constant of its lag state, when it has one), shared by the samples;
* ``selector``: which terms to add (:class:`~.selector.Selector`; :class:`~.selector.GreedySelector`: greedy
  forward selection with the catalogue's acceptance rule, at most a few terms); the fits and the rule are
  passed in as callables;
* ``result``: a discovered term as the verdict and the report state it (:class:`~.result.DiscoveredTerm`).

The diagnosis (``harness.analysis.diagnosis``) runs it after its catalogue stage when that stage leaves
structure beyond the noise (verdict "unexplained" or "+ unexplained remainder"): clean data cost nothing extra.
Layering: discovery imports only ``harness.analysis.core``, ``harness.data``, ``harness.sim`` and ``fmu_src``;
the diagnosis imports it.
"""
from .library import Library, TermLibrary, TermParam, default_library
from .result import DiscoveredTerm, discovered_term, term_json
from .selector import GreedySelector, Path, Selector, Step

__all__ = ["Library", "TermLibrary", "TermParam", "default_library", "DiscoveredTerm", "discovered_term",
           "term_json", "GreedySelector", "Path", "Selector", "Step"]
