# Scale-out (owner: deploy): three kdrayd replicas and a sharded fourth
# behind HAProxy on deploy/haproxy/kdray.cfg, loopback only, ~15 s: routing
# by scene name, /v1/ready checks, and a replica killed with SIGKILL and
# restarted under wrk load with zero failed client requests.
# haproxy and wrk: tests/cmake/required_tools.cmake (configure fails without).
add_test(NAME cluster
         COMMAND ${KDRAY_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_cluster.py
                 $<TARGET_FILE:kdrayd> ${KDRAY_HAPROXY}
                 ${PROJECT_SOURCE_DIR}/scenes/default.glb 12)
set_tests_properties(cluster PROPERTIES TIMEOUT 300)

# The configuration itself parses (haproxy -c), map file included.
add_test(NAME deploy_haproxy_config
         COMMAND ${CMAKE_COMMAND} -E env
                 KDRAY_SCENE_MAP=${PROJECT_SOURCE_DIR}/deploy/haproxy/kdray-scenes.map
                 ${KDRAY_HAPROXY} -c -f ${PROJECT_SOURCE_DIR}/deploy/haproxy/kdray.cfg)

# Kubernetes manifests (deploy/kubernetes) against the Kubernetes API
# schemas (npm kubernetes-models, installed by ./scripts/dev deps; offline)
# plus cross checks; --self-test breaks copies in 14 ways, each must fail.
add_test(NAME k8s_manifests
         COMMAND ${KDRAY_NODE} ${CMAKE_CURRENT_SOURCE_DIR}/k8s/validate.mjs --self-test
                 ${PROJECT_SOURCE_DIR}/deploy/kubernetes/kdray.yaml)
