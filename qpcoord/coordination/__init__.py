"""The thesis's coordination schemes (chapters 4 and 5), built on the kinematics layer.

=================  ==================================================================
module             holds
=================  ==================================================================
``geometry``       1-forms, Lie brackets, involutivity (ch. 4)
``potentials``     potential functions and their gradients and Hessians (ch. 5)
``extensions``     rigid and soft extensions (Defs 5.2-5.4)
``curvature``      Hessian-direction and complementary-form schemes (§5.4-5.5)
``schemes``        one scheme class per thesis method (``qc.schemes``)
``task_manifold``  fibres of the task map, self-motion
``periodicity``    closure errors, Poincaré sections, periods (``qc.analysis``)
=================  ==================================================================
"""
