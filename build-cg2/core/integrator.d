build-cg2/core/integrator.o: core/integrator.c core/integrator.h \
 core/sampler.h core/scene.h core/image.h core/vec.h core/path.h \
 core/bsdf.h core/geometry.h core/lights.h core/params.h
core/integrator.h:
core/sampler.h:
core/scene.h:
core/image.h:
core/vec.h:
core/path.h:
core/bsdf.h:
core/geometry.h:
core/lights.h:
core/params.h:
