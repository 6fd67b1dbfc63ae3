/* A parsed JSON document that can be destroyed without allocating.
 *
 * nlohmann::json's destructor moves a container's children onto a
 * heap-allocated stack before destroying them (so that a deep document does
 * not overflow the C stack): it allocates, inside a noexcept destructor, and
 * an allocation that fails there terminates the process
 * (tests/cli_alloc_failures.sh found it, at the end of every glTF write).
 * Emptied from its leaves up, a document only destroys empty containers,
 * which allocate nothing. The recursion stops at DR_JSON_RELEASE_DEPTH: a
 * deeper subtree (no glTF file has one) is left to nlohmann's own loop. */
#ifndef DR_JSON_RELEASE_H
#define DR_JSON_RELEASE_H

#include <nlohmann/json.hpp>

#define DR_JSON_RELEASE_DEPTH 64

inline void dr_json_release(nlohmann::json &j, int depth = 0) noexcept
{
    if (depth >= DR_JSON_RELEASE_DEPTH)
        return;
    if (j.is_array()) {
        auto &a = j.get_ref<nlohmann::json::array_t &>();
        for (auto &child : a)
            dr_json_release(child, depth + 1);
        a.clear();
    } else if (j.is_object()) {
        auto &o = j.get_ref<nlohmann::json::object_t &>();
        for (auto &kv : o)
            dr_json_release(kv.second, depth + 1);
        o.clear();
    }
}

/* The document, released (above) before it is destroyed. */
struct DrJsonDocument {
    nlohmann::json j;
    explicit DrJsonDocument(nlohmann::json &&parsed) : j(std::move(parsed)) {}
    DrJsonDocument(const DrJsonDocument &) = delete;
    DrJsonDocument &operator=(const DrJsonDocument &) = delete;
    ~DrJsonDocument() { dr_json_release(j); }
};

#endif
