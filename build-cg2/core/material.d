build-cg2/core/material.o: core/material.c core/material.h core/bsdf.h \
 core/vec.h core/geometry.h core/scene.h core/image.h
core/material.h:
core/bsdf.h:
core/vec.h:
core/geometry.h:
core/scene.h:
core/image.h:
