build-cg2/core/bsdf.o: core/bsdf.c core/bsdf.h core/vec.h
core/bsdf.h:
core/vec.h:
