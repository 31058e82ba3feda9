"""The multibody mechanics: rotations (:mod:`.so3`), the spine model of rigid vertebrae and passive elements
(:mod:`.model`), the force laws (:mod:`.elements`), the batched static-equilibrium solver (:mod:`.solve`) and the
intradiscal-pressure formulas (:mod:`.idp`). The bottom layer: it imports no other
``lumbar`` module (see docs/design.md)."""
