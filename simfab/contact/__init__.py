"""Contact against a rigid object: IMLS signed-distance field and a log barrier on it.

- :mod:`simfab.contact.imls`: Kolluri's implicit moving least squares (IMLS) surface of a rigid
  object O from its vertices and normals; value, gradient and Hessian evaluated in one Warp launch,
  neighbours read from per-cell lists built once in O's body frame. Sign convention: psi > 0 inside O, psi < 0 outside.
- :mod:`simfab.contact.barrier`: IPC-style log barrier on the distance d = -psi, with energy,
  gradient and Hessian side by side and the chain rule onto points interpolated from mesh vertices.
"""
