// Why a secure participant was refused. Fast DDS 2.9 says only "Problem creating RTPSParticipant";
// this repeats the checks its builtin plugins make on an identity's files (with OpenSSL, as they
// do) and names the first that fails: certificate not from this CA, key not matching, a signature
// that does not verify, the permissions' subject or domains.
#include "poise/dds/participant.h"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>

#include <fstream>
#include <memory>
#include <regex>
#include <sstream>

namespace poise::dds {
namespace {

template <class T, void (*Free)(T*)>
struct Deleter {
  void operator()(T* p) const { Free(p); }
};
void bio_free(BIO* b) { BIO_free_all(b); }
using Bio = std::unique_ptr<BIO, Deleter<BIO, bio_free>>;
using X509Ptr = std::unique_ptr<X509, Deleter<X509, X509_free>>;
using KeyPtr = std::unique_ptr<EVP_PKEY, Deleter<EVP_PKEY, EVP_PKEY_free>>;
using Pkcs7Ptr = std::unique_ptr<PKCS7, Deleter<PKCS7, PKCS7_free>>;
using StorePtr = std::unique_ptr<X509_STORE, Deleter<X509_STORE, X509_STORE_free>>;

std::string openssl_error() {
  const unsigned long e = ERR_get_error();
  ERR_clear_error();
  if (e == 0) {
    return "no detail";
  }
  char text[256];
  ERR_error_string_n(e, text, sizeof text);
  return text;
}

Bio open_file(const std::string& path) { return Bio(BIO_new_file(path.c_str(), "r")); }

X509Ptr read_cert(const std::string& path) {
  const Bio bio = open_file(path);
  return X509Ptr(bio ? PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr) : nullptr);
}

std::string subject_rfc2253(X509* cert) {
  const Bio out(BIO_new(BIO_s_mem()));
  X509_NAME_print_ex(out.get(), X509_get_subject_name(cert), 0, XN_FLAG_RFC2253);
  char* data = nullptr;
  const long n = BIO_get_mem_data(out.get(), &data);
  return std::string(data, static_cast<size_t>(n));
}

/// Verifies an S/MIME file signed by the CA; on success `content` is the signed text.
std::string verify_smime(const std::string& path, X509* ca, std::string* content) {
  const Bio in = open_file(path);
  BIO* detached = nullptr;
  const Pkcs7Ptr p7(in ? SMIME_read_PKCS7(in.get(), &detached) : nullptr);
  const Bio data(detached);
  if (!p7) {
    return path + " is not an S/MIME signed file (" + openssl_error() + ")";
  }
  const StorePtr store(X509_STORE_new());
  X509_STORE_add_cert(store.get(), ca);
  const Bio out(BIO_new(BIO_s_mem()));
  if (PKCS7_verify(p7.get(), nullptr, store.get(), data.get(), out.get(), PKCS7_TEXT) != 1) {
    return "the signature of " + path + " is invalid: not signed by this ca.pem, or the file was "
           "edited after signing (" + openssl_error() + "); sign it again with "
           "tools/security/make_security.sh";
  }
  char* text = nullptr;
  const long n = BIO_get_mem_data(out.get(), &text);
  content->assign(text, static_cast<size_t>(n));
  return {};
}

/// True when the <domains> of `xml` (ids and id ranges) include `domain`; nullopt if none listed.
std::optional<bool> grants_domain(const std::string& xml, int domain) {
  bool any = false;
  const std::regex id("<id>\\s*([0-9]+)\\s*</id>");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), id); it != std::sregex_iterator(); ++it) {
    any = true;
    if (std::stoi((*it)[1]) == domain) {
      return true;
    }
  }
  const std::regex range("<id_range>\\s*<min>\\s*([0-9]+)\\s*</min>\\s*(?:<max>\\s*([0-9]+)\\s*</max>)?\\s*</id_range>");
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), range); it != std::sregex_iterator(); ++it) {
    any = true;
    const int lo = std::stoi((*it)[1]);
    const int hi = (*it)[2].matched ? std::stoi((*it)[2]) : 232;
    if (domain >= lo && domain <= hi) {
      return true;
    }
  }
  return any ? std::optional<bool>(false) : std::nullopt;
}

}  // namespace

std::string check_security_files(const SecurityConfig& config, int domain) {
  const std::string ca_path = config.dir + "/ca.pem";
  const std::string id_dir = config.dir + "/" + config.identity;
  const X509Ptr ca = read_cert(ca_path);
  if (!ca) {
    return ca_path + " is not a PEM certificate (" + openssl_error() + ")";
  }
  const X509Ptr cert = read_cert(id_dir + "/cert.pem");
  if (!cert) {
    return id_dir + "/cert.pem is not a PEM certificate (" + openssl_error() + ")";
  }
  if (X509_verify(cert.get(), X509_get0_pubkey(ca.get())) != 1) {
    ERR_clear_error();
    return id_dir + "/cert.pem was not issued by " + ca_path + " (an identity of another CA)";
  }
  if (X509_cmp_current_time(X509_get0_notAfter(cert.get())) < 0) {
    return id_dir + "/cert.pem has expired";
  }
  {
    const Bio bio = open_file(id_dir + "/key.pem");
    const KeyPtr key(bio ? PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr) : nullptr);
    if (!key) {
      return id_dir + "/key.pem is not a PEM private key (" + openssl_error() + ")";
    }
    if (X509_check_private_key(cert.get(), key.get()) != 1) {
      ERR_clear_error();
      return id_dir + "/key.pem is not the key of " + id_dir + "/cert.pem";
    }
  }
  std::string governance;
  std::string problem = verify_smime(config.dir + "/governance.p7s", ca.get(), &governance);
  if (!problem.empty()) {
    return problem;
  }
  if (grants_domain(governance, domain) == std::optional<bool>(false)) {
    return config.dir + "/governance.p7s has no rule for domain " + std::to_string(domain) +
           " (POISE_SEC_DOMAINS of make_security.sh)";
  }
  std::string permissions;
  problem = verify_smime(id_dir + "/permissions.p7s", ca.get(), &permissions);
  if (!problem.empty()) {
    return problem;
  }
  std::smatch m;
  if (std::regex_search(permissions, m, std::regex("<subject_name>([^<]*)</subject_name>"))) {
    const std::string subject = subject_rfc2253(cert.get());
    if (m[1] != subject) {
      return id_dir + "/permissions.p7s grants '" + std::string(m[1]) +
             "', not the certificate's subject '" + subject +
             "' (Fast DDS 2.9 compares the RFC 2253 form: CN=..., O=..., C=...)";
    }
  }
  if (grants_domain(permissions, domain) == std::optional<bool>(false)) {
    return id_dir + "/permissions.p7s does not grant domain " + std::to_string(domain);
  }
  return {};
}

}  // namespace poise::dds
