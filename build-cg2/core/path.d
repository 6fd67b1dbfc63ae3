build-cg2/core/path.o: core/path.c core/path.h core/bsdf.h core/vec.h \
 core/geometry.h core/scene.h core/image.h core/integrator.h \
 core/sampler.h core/lights.h core/params.h core/accel.h core/material.h
core/path.h:
core/bsdf.h:
core/vec.h:
core/geometry.h:
core/scene.h:
core/image.h:
core/integrator.h:
core/sampler.h:
core/lights.h:
core/params.h:
core/accel.h:
core/material.h:
